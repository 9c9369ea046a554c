"""Defaults shared by the library and the command line, in a module that imports nothing (the
command line reads them before it loads the numerical code)."""

#: Default largest K tried when K is chosen (Skill.learn, the CLI). The demonstrations of the
#: simulated tasks need 8-20 components per space (benchmarks/bench_selection.py).
MAX_COMPONENTS = 30
