"""Sphinx glue for pbdkit's docs: references by public name, tables of names and commands.

- References by the names users write resolve to where an object is documented, its defining
  module: ``pbdkit.Skill`` to ``pbdkit.skill._skill.Skill``, ``pbdkit.sim.register_task`` to
  ``pbdkit.sim._task_registry.register_task``, and a short name to what the current module imports.
- ``.. pbdkit-names:: PACKAGE`` is a table of a package's ``__all__``: each name, where it lives
  and the first paragraph of its docstring; ``.. pbdkit-modules::`` a table of modules;
  ``.. pbdkit-cli::`` the ``--help`` of every ``pbdkit`` command. The module pages are
  generated (:func:`_generate_pages`).
- Every name in the ``__all__`` of :data:`PUBLIC_PACKAGES` must be documented somewhere: a new
  public name without a page fails the build.
"""

from __future__ import annotations

import importlib
import inspect
import json
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.addnodes import pending_xref
from sphinx.application import Sphinx
from sphinx.environment import BuildEnvironment
from sphinx.ext import napoleon
from sphinx.pycode import ModuleAnalyzer
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

logger = logging.getLogger(__name__)

#: Packages whose ``__all__`` is public API: each name must be documented.
PUBLIC_PACKAGES = (
    "pbdkit",
    "pbdkit.prob",
    "pbdkit.motion",
    "pbdkit.robots",
    "pbdkit.collision",
    "pbdkit.data",
    "pbdkit.reproduction",
    "pbdkit.skill",
    "pbdkit.datasets",
    "pbdkit.sim",
    "pbdkit.vision",
    "pbdkit.ros",
    "pbdkit.apps",
)

SRC = Path(__file__).resolve().parents[2] / "src"

# ---------------------------------------------------------------------------------------------
# Public names -> where they are documented


def _import(path: str) -> tuple[Any, Any, str] | None:
    """``(object, its parent, its attribute name)`` for a dotted path, or None if nothing has
    that path. The object is :data:`_MISSING` for an attribute a class declares but does not
    hold (an instance attribute, a dataclass field without a default): its docstring's
    "Attributes" section documents it."""
    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        modname = ".".join(parts[:i])
        try:
            obj: Any = importlib.import_module(modname)
        except ImportError:
            continue
        parent: Any = None
        for k, attr in enumerate(parts[i:], start=i):
            parent, obj = obj, getattr(obj, attr, _MISSING)
            if obj is _MISSING and not (inspect.isclass(parent) and k == len(parts) - 1):
                return None
        return obj, parent, parts[-1]
    return None


_MISSING = object()


def canonical_name(path: str, env: BuildEnvironment) -> tuple[str | None, bool]:
    """Where the object ``path`` names is documented (None if nowhere), and whether it exists."""
    found = _import(path)
    if found is None:
        return None, False
    obj, parent, attr = found
    domain: Any = env.get_domain("py")
    if isinstance(obj, ModuleType):
        return (obj.__name__ if obj.__name__ in domain.modules else None), True
    if (inspect.isclass(obj) or inspect.isroutine(obj)) and hasattr(obj, "__qualname__"):
        name = _public_home(obj.__module__, obj.__qualname__, domain)
    elif inspect.isclass(parent):  # a property or an attribute
        owner, _ = canonical_name(f"{parent.__module__}.{parent.__qualname__}", env)
        name = f"{owner}.{attr}"
        # numpy docstrings document "a, b : type" as one attribute
        grouped = [
            n
            for n in domain.objects
            if n.startswith(f"{owner}.") and attr in n[len(owner) + 1 :].split(", ")
        ]
        if name not in domain.objects and len(grouped) == 1:
            name = grouped[0]
    elif isinstance(parent, ModuleType):  # data: documented in one of the package's modules
        prefix = parent.__name__ + "."
        homes = [n for n in domain.objects if n.startswith(prefix) and n.endswith("." + attr)]
        # a module that re-exports a constant in its __all__ documents it too: the home is
        # the module that assigns it
        assigned = [h for h in homes if _assigns(h.rpartition(".")[0], attr)]
        name = (assigned or homes)[0] if len(assigned or homes) == 1 else f"{prefix}{attr}"
    else:
        return None, True
    documented = name in domain.objects
    # an attribute the class does not hold exists only as far as its docstring says so
    return (name if documented else None), documented or obj is not _MISSING


def _public_home(module: str, qualname: str, domain: Any) -> str:
    """Where an object defined in ``module`` is documented: its module's page if that module is
    public, else the page of the nearest public package above it, which exports it (a private
    module's names are documented by the package that curates them)."""
    name = f"{module}.{qualname}"
    parts = module.split(".")
    while name not in domain.objects and any(p.startswith("_") for p in parts):
        parts = parts[:-1]
        name = f"{'.'.join(parts)}.{qualname}"
    return name


def _assigns(modname: str, attr: str) -> bool:
    source = inspect.getsource(importlib.import_module(modname))
    return re.search(rf"^{re.escape(attr)}\s*[:=]", source, re.MULTILINE) is not None


def _resolve_alias(
    app: Sphinx, env: BuildEnvironment, node: pending_xref, contnode: nodes.TextElement
) -> nodes.reference | None:
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip(".~")
    module, cls = node.get("py:module"), node.get("py:class")
    candidates = [f"{module}.{cls}.{target}"] if module and cls else []
    if module:
        candidates.append(f"{module}.{target}")
    if target.startswith("pbdkit"):
        candidates.append(target)
    exists = False
    for candidate in candidates:
        name, found = canonical_name(candidate, env)
        exists = exists or found
        if name is not None:
            domain: Any = env.get_domain("py")
            typ = "mod" if name in domain.modules else "obj"
            ref: nodes.reference | None = domain.resolve_xref(
                env, node["refdoc"], app.builder, typ, name, node, contnode
            )
            return ref
    # An object that exists but has no page (private, or outside its module's __all__) stays
    # text; a name that no longer exists falls through to Sphinx's warning.
    return contnode if exists else None


def _summary(obj: Any) -> str:
    """The first paragraph of an object's docstring, on one line."""
    doc = inspect.getdoc(obj) or ""
    return " ".join(doc.split("\n\n", 1)[0].split())


def _first_paragraph(package: ModuleType, name: str) -> str:
    obj = getattr(package, name)
    if isinstance(obj, ModuleType) or inspect.isclass(obj) or inspect.isroutine(obj):
        return _summary(obj)
    # data: its ``#:`` comment in the module that assigns it
    homes = [package.__name__, *_public_modules(package)]
    home = next((m for m in homes if _assigns(m, name)), package.__name__)
    doc = "\n".join(ModuleAnalyzer.for_module(home).find_attr_docs().get(("", name), []))
    return " ".join(doc.split("\n\n", 1)[0].split())


def _defined_in(module: ModuleType, name: str) -> bool:
    obj = getattr(module, name)
    if isinstance(obj, ModuleType):
        return False
    if inspect.isclass(obj) or inspect.isroutine(obj):
        return getattr(obj, "__module__", None) == module.__name__
    return _assigns(module.__name__, name)


class PublicNames(SphinxDirective):
    """``.. pbdkit-names:: PACKAGE``: a table of the package's ``__all__``, if it re-exports
    names from its modules (nothing for a package whose names are all its own)."""

    required_arguments = 1

    def run(self) -> list[nodes.Node]:
        package = importlib.import_module(self.arguments[0])
        names = sorted(getattr(package, "__all__", ()), key=str.lower)
        if all(_defined_in(package, name) for name in names):
            return []  # documented on the package's own page below
        rows = [
            ".. list-table::",
            "   :header-rows: 1",
            "   :widths: 30 70",
            "",
            "   * - name",
            "     - what it is",
        ]
        for name in names:
            obj = getattr(package, name)
            role = "mod" if isinstance(obj, ModuleType) else "obj"
            rows += [
                f"   * - :py:{role}:`{package.__name__}.{name}`",
                f"     - {_first_paragraph(package, name)}",
            ]
        container = nodes.container()
        nested_parse_with_titles(
            self.state, StringList(rows, source=self.get_source_info()[0]), container
        )
        return container.children


class ModuleTable(SphinxDirective):
    """``.. pbdkit-modules:: MODULE...``: a table of the modules (each linked to its page, with
    its docstring's first paragraph) and their pages in the toctree; :data:`LAYERS` if none."""

    optional_arguments = 100

    def run(self) -> list[nodes.Node]:
        names = self.arguments or list(LAYERS)
        rows = [".. toctree::", "   :hidden:", ""]
        rows += [f"   /{GENERATED}/{name}" for name in names]
        rows += ["", ".. list-table::", "   :widths: 30 70", ""]
        for name in names:
            module = importlib.import_module(name)
            rows += [f"   * - :py:mod:`{name}`", f"     - {_summary(module)}"]
        container = nodes.container()
        source = self.get_source_info()[0]
        nested_parse_with_titles(self.state, StringList(rows, source=source), container)
        return container.children


# Run in a process of its own: autodoc rewrites the signatures of the functions it documents
# (autodoc_preserve_defaults), and typer builds the command's options from those signatures.
_HELP_SCRIPT = """
import json, sys
import typer.main
from typer.testing import CliRunner
from pbdkit.apps._cli import app
root = typer.main.get_command(app)
calls = [[]]
for name, command in getattr(root, "commands", {}).items():  # a group's commands too (ros)
    calls += [[name], *([name, sub] for sub in getattr(command, "commands", {}))]
env = {"COLUMNS": "96", "NO_COLOR": "1", "TERM": "dumb"}
out = {}
for args in calls:
    result = CliRunner().invoke(app, [*args, "--help"], prog_name="pbdkit", env=env)
    if result.exit_code != 0:
        sys.exit(f"pbdkit {' '.join(args)} --help failed: {result.output}")
    out[" ".join(args)] = result.output
print(json.dumps(out))
"""


class CommandHelp(SphinxDirective):
    """``.. pbdkit-cli::``: the ``--help`` of the ``pbdkit`` command and of each subcommand, as
    a terminal 96 columns wide shows it, a section per subcommand."""

    def run(self) -> list[nodes.Node]:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), *sys.path])}
        proc = subprocess.run(
            [sys.executable, "-c", _HELP_SCRIPT], env=env, capture_output=True, text=True
        )
        if proc.returncode != 0:
            raise self.error(f"the pbdkit command's help failed: {proc.stderr.strip()}")
        rows: list[str] = []
        for command, output in json.loads(proc.stdout).items():
            if command:
                title = f"pbdkit {command}"
                rows += [title, "-" * len(title), ""]
            text = "\n".join(line.rstrip() for line in output.splitlines()).strip("\n")
            rows += ["::", "", *("   " + line for line in text.splitlines()), ""]
        container = nodes.container()
        source = self.get_source_info()[0]
        nested_parse_with_titles(self.state, StringList(rows, source=source), container)
        return container.children


def _check_public(app: Sphinx, env: BuildEnvironment) -> None:
    for package_name in PUBLIC_PACKAGES:
        package = importlib.import_module(package_name)
        for name in package.__all__:
            if canonical_name(f"{package_name}.{name}", env)[0] is None:
                logger.warning(
                    "%s.%s is public (in __all__) but documented nowhere in the API reference",
                    package_name,
                    name,
                )


# ---------------------------------------------------------------------------------------------
# autodoc: what a class page shows


def _skip_member(
    app: Sphinx, what: str, name: str, obj: Any, skip: bool, options: Any
) -> bool | None:
    if what in ("class", "exception"):
        # scikit-learn's generated metadata-routing methods (set_fit_request, ...) document
        # scikit-learn, with references into its own docs
        if getattr(obj, "__module__", "").startswith("sklearn"):
            return True
        # a class member without a docstring or a ``#:`` comment is listed in the class's
        # "Attributes" section, or is not API (undoc-members is for the modules' __all__)
        own = inspect.getdoc(obj)
        if (not own or own == inspect.getdoc(type(obj))) and not _has_attr_doc(app, name):
            return True
    return None


def _has_attr_doc(app: Sphinx, name: str) -> bool:
    """Whether the class autodoc is documenting has a ``#:`` comment for attribute ``name``."""
    current = getattr(app.env, "current_document", None)
    if current is not None and hasattr(current, "autodoc_module"):  # Sphinx >= 8.2
        module, cls = current.autodoc_module, current.autodoc_class
    else:
        temp = app.env.temp_data
        module, cls = temp.get("autodoc:module"), temp.get("autodoc:class")
    if not module or not cls:
        return False
    return (cls, name) in ModuleAnalyzer.for_module(module).find_attr_docs()


_SECTION = re.compile(r"^-{3,}\s*$")


def _strip_documented_attributes(
    app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    """Drop from a class's "Attributes" section the entries that are properties with docstrings:
    autodoc documents those, and two descriptions of one name are a duplicate."""
    if what != "class" or "Attributes" not in lines:
        return
    start = lines.index("Attributes")
    if start + 1 >= len(lines) or not _SECTION.match(lines[start + 1]):
        return
    end = next(
        (
            i
            for i in range(start + 2, len(lines) - 1)
            if lines[i] and not lines[i][0].isspace() and _SECTION.match(lines[i + 1])
        ),
        len(lines),
    )
    kept: list[str] = []
    entry: list[str] = []

    def flush() -> None:
        if not entry:
            return
        names = [n.strip() for n in entry[0].split(" : ")[0].split(",")]
        if not all(_has_own_doc(obj, n) for n in names):
            kept.extend(entry)
        entry.clear()

    for line in lines[start + 2 : end]:
        if line and not line[0].isspace():
            flush()
        entry.append(line)
    flush()
    body = [line for line in kept if line.strip()]
    lines[start:end] = ["Attributes", lines[start + 1], *kept] if body else []


def _has_own_doc(cls: Any, name: str) -> bool:
    member = inspect.getattr_static(cls, name, None)
    return isinstance(member, property) and bool(member.__doc__)


# ---------------------------------------------------------------------------------------------
# One page per module, generated


#: The layers, bottom up: each gets a page of its own, and each of its public modules.
LAYERS = PUBLIC_PACKAGES[1:]
GENERATED = "api/generated"


def _public_modules(package: ModuleType) -> list[str]:
    return [
        info.name
        for info in pkgutil.iter_modules(package.__path__, package.__name__ + ".")
        if not info.name.rpartition(".")[2].startswith("_")
    ]


def module_page(name: str) -> tuple[str, list[str]]:
    """The reST page of a public module or package, and the public modules it lists.

    A package's page documents the names of its ``__all__``, wherever they are defined: its
    implementation modules are private (``_name.py``) and have no page of their own."""
    module = importlib.import_module(name)
    lines = [name, "=" * len(name), "", f".. automodule:: {name}"]
    children = _public_modules(module) if hasattr(module, "__path__") else []
    if children:
        lines += ["", ".. rubric:: Modules", "", f".. pbdkit-modules:: {' '.join(children)}"]
    return "\n".join(lines) + "\n", children


def _generate_pages(app: Sphinx) -> None:
    """Write a page per module of :data:`LAYERS` (pkgutil finds them: a module added, split or
    renamed needs no edit here), rewriting only the pages that changed and removing the pages
    of modules that are gone."""
    folder = Path(app.srcdir) / GENERATED
    folder.mkdir(parents=True, exist_ok=True)
    pending, written = list(LAYERS), set()
    while pending:
        name = pending.pop()
        text, children = module_page(name)
        path = folder / f"{name}.rst"
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
        written.add(path.name)
        pending += children
    for stale in folder.glob("*.rst"):
        if stale.name not in written:
            stale.unlink()


def _napoleon_except_attributes(
    app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    # Napoleon reads the first line of an attribute's, a constant's or a property's docstring as
    # "type: description" at its first colon, and pbdkit's one-line descriptions have colons
    # ("True once a command has targeted the last step (with motion limits: once ..."); these
    # docstrings are plain paragraphs, with no numpy sections, so they are left as they are.
    if what not in ("attribute", "data", "property"):
        napoleon._process_docstring(app, what, name, obj, options, lines)


def setup(app: Sphinx) -> dict[str, Any]:
    app.setup_extension("sphinx.ext.napoleon")
    for listener in list(app.events.listeners["autodoc-process-docstring"]):
        if listener.handler is napoleon._process_docstring:
            app.disconnect(listener.id)
            app.connect("autodoc-process-docstring", _napoleon_except_attributes, listener.priority)
    app.connect("builder-inited", _generate_pages)
    app.connect("autodoc-skip-member", _skip_member)
    # before napoleon (priority 500) turns the section into directives
    app.connect("autodoc-process-docstring", _strip_documented_attributes, priority=400)
    app.connect("missing-reference", _resolve_alias)
    app.connect("env-check-consistency", _check_public)
    app.add_directive("pbdkit-names", PublicNames)
    app.add_directive("pbdkit-modules", ModuleTable)
    app.add_directive("pbdkit-cli", CommandHelp)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
