"""Defaults shared by the library and the command line, in a module that imports nothing (the
command line reads them before it loads the numerical code)."""

#: Default largest K tried when K is chosen (Skill.learn, the CLI). The demonstrations of the
#: simulated tasks need 8-20 components per space (benchmarks/bench_selection.py).
MAX_COMPONENTS = 30

#: The most trials an evaluation runs (pbdkit.sim.evaluate, ``pbdkit evaluate --trials``). A trial
#: is a physics run of every controller, seconds each: 10**5 of them are days of computing. A
#: larger count is refused at once (issue 36: --trials 1000000000 grew memory by 11 MB/s drawing
#: the placements before the first trial).
MAX_TRIALS = 100_000


def install_hint(extra: str) -> str:
    """How to install one of pbdkit's extras (``sim``, ``view``, ``ros``), for a message.

    pbdkit is installed from its source tree, not from a package index, so the command names the
    checkout (or the wheel ``make wheel`` builds), not a package on PyPI.
    """
    return (
        f"pip install -e '.[{extra}]' in the pbdkit checkout, or "
        f"pip install 'dist/pbdkit-*.whl[{extra}]' (make wheel)"
    )
