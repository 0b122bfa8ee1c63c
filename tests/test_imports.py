"""The package's modules import each other one way, and only public names.

Read with :mod:`ast` from the source (no module is imported), every import counts:
module level, inside functions, relative ones.  The graph's edges:

- ``import a.b.c`` / ``from a.b.c import x``: an edge to ``a.b.c``; and, when ``x``
  is a submodule (``from cgda_jax import distance``), to ``a.b.c.x`` instead of
  the package.
- Importing ``a.b.c`` executes the packages ``a.b`` first: an edge to each package
  on the way that the importing module is not itself inside (a module inside
  ``a.b`` runs only once ``a.b`` has started, so ``from cgda_jax.experiment.config
  import X`` in ``experiment/run.py`` is no loop, while ``from cgda_jax.experiment
  import X`` there is one: the package imports ``run``).
- A package ``__init__`` that re-exports lazily (PEP 562: ``_LAZY`` tables of module
  names, imports under ``if TYPE_CHECKING:``) has an edge to every module it names,
  because ``from cgda_jax import Robot`` imports ``cgda_jax.sim.robot``.  In any
  other module, imports under ``if TYPE_CHECKING:`` never run and do not count.

The checks: no import loop (the failure names the loop), the experiment layer's
modules in their documented order (each imports only those before it), no
``_private`` name taken from another module, private modules (``sim/_mujoco_env.py``)
imported only from inside their own package, nothing taken from the re-export
package ``cgda_jax`` itself but its submodules and ``__version__``, and nothing
outside ``cgda_jax/cli/`` importing the CLI.
"""

from __future__ import annotations

import ast
import pathlib
from collections.abc import Iterator, Mapping

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1] / "cgda_jax"
TOP = "cgda_jax"


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def module_files(root: pathlib.Path = ROOT) -> dict[str, pathlib.Path]:
    """Module name -> file, for every ``.py`` file of the package."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = (root.name, *path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id.endswith("TYPE_CHECKING")) or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST, keep_type_checking: bool) -> Iterator[ast.stmt]:
    """Every Import / ImportFrom in the tree, at any depth."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            children = (node.body if keep_type_checking else []) + node.orelse
        else:
            children = list(ast.iter_child_nodes(node))
        for child in children:
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                yield child
            stack.append(child)


class Imports:
    """What one module imports: the edges, and each (module, name) taken by ``from``."""

    def __init__(self) -> None:
        self.targets: set[str] = set()
        self.names: list[tuple[str, str, int]] = []  # (from module, name, line)


def read_imports(modules: Mapping[str, pathlib.Path],
                 type_only: bool = False) -> dict[str, Imports]:
    """Module -> its imports of the package's own modules (``type_only``: those
    under ``if TYPE_CHECKING:`` too, in every module)."""
    out = {}
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        tree = ast.parse(path.read_text(), str(path))
        found = Imports()
        for node in _imports(tree, keep_type_checking=is_package or type_only):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.split(".")[0] == TOP:
                        found.targets.add(_existing(alias.name, modules))
                continue
            base = node.module or ""
            if node.level:  # relative: from the package (or its parents)
                package = name if is_package else name.rpartition(".")[0]
                for _ in range(node.level - 1):
                    package = package.rpartition(".")[0]
                base = f"{package}.{base}" if base else package
            if base.split(".")[0] != TOP:
                continue
            base = _existing(base, modules)
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in modules:  # from package import submodule
                    found.targets.add(sub)
                else:
                    found.targets.add(base)
                    found.names.append((base, alias.name, node.lineno))
        if is_package:  # lazy re-exports: module names in string constants
            for const in ast.walk(tree):
                if (isinstance(const, ast.Constant) and isinstance(const.value, str)
                        and const.value in modules and const.value != name):
                    found.targets.add(const.value)
        out[name] = found
    return out


def _existing(dotted: str, modules: Mapping[str, pathlib.Path]) -> str:
    """The longest prefix of ``dotted`` that is one of the package's modules."""
    parts = dotted.split(".")
    while parts and ".".join(parts) not in modules:
        parts.pop()
    assert parts, f"{dotted} is no module of {TOP}"
    return ".".join(parts)


def _inside(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def import_graph(imports: Mapping[str, Imports]) -> dict[str, set[str]]:
    """Module -> the package's modules that importing it executes directly."""
    graph: dict[str, set[str]] = {name: set() for name in imports}
    for name, found in imports.items():
        for target in found.targets:
            parts = target.split(".")
            for i in range(1, len(parts) + 1):
                step = ".".join(parts[:i])
                if step in graph and step != name and (
                        step == target or not _inside(name, step)):
                    graph[name].add(step)
    return graph


def find_cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """One loop (``[a, b, ..., a]``) for each strongly connected group of modules
    that import each other (Tarjan), a module importing itself included."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[set[str]] = []

    def visit(v: str) -> None:  # graph of ~100 nodes: recursion is fine
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.add(w)
                if w == v:
                    break
            if len(group) > 1 or v in graph.get(v, ()):
                groups.append(group)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [_loop_in(group, graph) for group in groups]


def _loop_in(group: set[str], graph: Mapping[str, set[str]]) -> list[str]:
    """A shortest loop through the group's first module (breadth-first)."""
    start = min(group)
    paths = {start: [start]}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph.get(v, ())):
                if w == start:
                    return paths[v] + [start]
                if w in group and w not in paths:
                    paths[w] = paths[v] + [w]
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"no loop in {sorted(group)}")  # pragma: no cover


MODULES = module_files()
IMPORTS = read_imports(MODULES)
GRAPH = import_graph(IMPORTS)


# ------------------------------------------------------------------ the finder


def test_cycle_finder_names_every_loop_of_a_synthetic_graph():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(),
             "e": {"e"}, "f": {"g"}, "g": {"f"}, "h": {"a"}}
    loops = sorted(find_cycles(graph))
    assert loops == [["a", "b", "c", "a"], ["e", "e"], ["f", "g", "f"]]
    assert find_cycles({"a": {"b"}, "b": {"c"}, "c": set(), "d": {"a", "c"}}) == []


def test_the_graph_follows_packages_submodules_and_relative_imports(tmp_path):
    pkg = tmp_path / TOP
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text(
        "_LAZY = {'thing': 'cgda_jax.sub.one'}\n"
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from cgda_jax.two import Two\n")
    (pkg / "two.py").write_text("def f():\n    from cgda_jax import sub\n")
    (pkg / "sub" / "__init__.py").write_text("from .one import x as x\n")
    (pkg / "sub" / "one.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from cgda_jax.two import Two\n"
        "def g():\n    from cgda_jax.sub import x\n    from ..two import _hidden\n")
    modules = module_files(pkg)
    imports = read_imports(modules)
    graph = import_graph(imports)
    assert graph == {
        "cgda_jax": {"cgda_jax.sub", "cgda_jax.sub.one", "cgda_jax.two"},
        "cgda_jax.sub": {"cgda_jax.sub.one"},
        "cgda_jax.sub.one": {"cgda_jax.sub", "cgda_jax.two"},
        "cgda_jax.two": {"cgda_jax.sub"},
    }
    assert sorted(find_cycles(graph)) == [["cgda_jax.sub", "cgda_jax.sub.one",
                                           "cgda_jax.sub"]]
    assert ("cgda_jax.two", "_hidden", 6) in imports["cgda_jax.sub.one"].names


# ------------------------------------------------------------------ the package


def test_the_package_is_read_whole():
    assert {"cgda_jax", "cgda_jax.cli", "cgda_jax.experiment.config",
            "cgda_jax.strategies.ie", "cgda_jax.sim.robot"} <= set(MODULES)
    assert GRAPH["cgda_jax"] >= {"cgda_jax.sim.robot", "cgda_jax.experiment"}


def test_no_import_loop():
    loops = [" -> ".join(loop) for loop in find_cycles(GRAPH)]
    assert not loops, "modules that import each other:\n" + "\n".join(loops)


def test_no_import_loop_with_type_only_imports():
    """Imports under ``if TYPE_CHECKING:`` never run, but a loop through one is
    still two modules that depend on each other (issue 40): none either."""
    graph = import_graph(read_imports(MODULES, type_only=True))
    loops = [" -> ".join(loop) for loop in find_cycles(graph)]
    assert not loops, "modules that import each other:\n" + "\n".join(loops)


#: The modules of two packages in their import order (their package docstrings).
ORDER = {
    "experiment": ("sections", "config", "demo_suite", "locate", "programs_key",
                   "rules", "build", "validate", "compute", "report", "load", "trajectory_file",
                   "figures", "run", "success_rate"),
    "cli": ("output", "list", "plot", "export", "track", "segment", "trials", "run",
            "demo", "app", "__main__"),
}


@pytest.mark.parametrize("package", sorted(ORDER))
def test_a_package_s_modules_import_only_those_before_them(package):
    order, package = ORDER[package], f"{TOP}.{package}"
    found = sorted(m.rpartition(".")[2] for m in MODULES
                   if m.startswith(package + "."))
    assert found == sorted(order)
    bad = []
    for k, short in enumerate(order):
        for target in GRAPH[f"{package}.{short}"]:
            if _inside(target, package):
                other = target.rpartition(".")[2]
                if target == package or order.index(other) >= k:
                    bad.append(f"{package}.{short} imports {target}")
    assert not bad, "\n".join(bad)


def test_no_private_name_is_taken_from_another_module():
    bad = [f"{name}:{line} takes {name_!r} from {source}"
           for name, found in IMPORTS.items()
           for source, name_, line in found.names
           if source != name and _is_private(name_)]
    assert not bad, "\n".join(bad)


def test_private_modules_are_imported_only_inside_their_package():
    bad = []
    for name, found in IMPORTS.items():
        for target in found.targets:
            parts = target.split(".")
            for i, part in enumerate(parts):
                owner = ".".join(parts[:i])
                if _is_private(part) and not _inside(name, owner):
                    bad.append(f"{name} imports {target}, private to {owner}")
    assert not bad, "\n".join(bad)


def test_nothing_but_submodules_and_the_version_comes_from_the_top_package():
    bad = [f"{name}:{line} takes {name_!r} from {TOP} (import it from the module "
           "that defines it)"
           for name, found in IMPORTS.items()
           for source, name_, line in found.names
           if source == TOP and name_ != "__version__"]
    assert not bad, "\n".join(bad)


def test_nothing_outside_the_cli_imports_it():
    bad = [f"{name} imports {target}" for name, targets in GRAPH.items()
           if not _inside(name, f"{TOP}.cli")
           for target in targets if _inside(target, f"{TOP}.cli")]
    assert not bad, "\n".join(bad)


def test_importing_the_experiment_package_leaves_jax_uninitialised():
    """A multi-process job joins JAX's distributed runtime before any JAX work
    (`cgda_jax.cli.trials.join_job`), so importing `cgda_jax.experiment` (the
    job's workers import it early) must not start a backend: evosax does at import,
    so the strategies are imported where they are used."""
    import subprocess
    import sys

    code = ("import cgda_jax.experiment, cgda_jax.experiment.success_rate, "
            "cgda_jax.cli.app\nfrom jax._src import xla_bridge as xb\n"
            "print(bool(xb._backends))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
