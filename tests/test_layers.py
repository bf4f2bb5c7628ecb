"""The layers of the code and the import graph between its modules.

The packages are layered, lowest first: rb_drake <- planning <- systems <- experiments <- rbp
(the command line). A module may import from its own layer and the layers below it, never from
one above; and no two modules may import each other, directly or through others. Every import
counts, also those inside functions (run later, but still a dependency), except those under
`if TYPE_CHECKING:` (for annotations only, never run). docs/architecture.md describes the
layers; these tests keep it true.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("rb_drake", "planning", "systems", "experiments", "rbp")  # lowest first

# What an experiment script may import from its own layer: the shared libraries, never another
# experiment script (run one with `rbp experiment NAME`, or move what it shares into these). An
# experiment that is a package (experiments/bench/) may import its own modules.
EXPERIMENT_LIBRARIES = frozenset({"experiments", "experiments.common", "experiments.sweep",
                                  "experiments.ompl_log", "experiments.arguments",
                                  "experiments.records"})


def experiment_of(module: str) -> str:
    """The experiment a module belongs to: experiments.NAME for experiments.NAME.anything."""
    return ".".join(module.split(".")[:2])



def module_files() -> dict[str, Path]:
    """Every module of the layered packages: dotted name -> file."""
    modules = {}
    for package in LAYERS:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return ((isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
            or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"))


def imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement of a module, at any depth, but none under `if TYPE_CHECKING:`
    (its `else:` branch runs, so counts)."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child):
                for other in child.orelse:
                    visit_node(other)
            else:
                visit_node(child)

    def visit_node(node: ast.AST) -> None:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        visit(node)

    visit(tree)
    return found


def imported_modules(name: str, path: Path, modules: dict[str, Path]) -> dict[str, int]:
    """The project's modules that module `name` imports -> the line of the first such import.
    `from pkg import x` counts as importing `pkg.x` when that is a module, else `pkg`; an
    import of a name that is not a module of the project (numpy, a package's attribute)
    counts as its longest prefix that is one, if any."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: dict[str, int] = {}

    def add(dotted: str, line: int) -> None:
        while dotted and dotted not in modules:
            dotted = dotted.rpartition(".")[0]
        if dotted and dotted != name:
            targets.setdefault(dotted, line)

    for node in imports(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(alias.name, node.lineno)
            continue
        base = node.module or ""
        if node.level:  # relative: from the module's package, one level up per extra dot
            anchor = package.split(".")
            anchor = anchor[:len(anchor) - (node.level - 1)]
            base = ".".join([*anchor, *([base] if base else [])])
        for alias in node.names:
            full = f"{base}.{alias.name}"
            add(full if full in modules else base, node.lineno)
    return targets


def layer(module: str) -> int:
    return LAYERS.index(module.split(".")[0])


@pytest.fixture(scope="module")
def graph() -> nx.DiGraph:
    """The import graph of the layered packages; each edge has the importing line."""
    modules = module_files()
    g = nx.DiGraph()
    g.add_nodes_from(modules)
    for name, path in modules.items():
        for target, line in imported_modules(name, path, modules).items():
            g.add_edge(name, target, line=line)
    return g


def test_the_graph_sees_the_imports(graph: nx.DiGraph) -> None:
    """The graph holds what it should: a top-level import, one inside a function, a
    relative one, and none from under `if TYPE_CHECKING:`."""
    assert graph.has_edge("planning.plan", "planning.easing")
    assert graph.has_edge("rbp.cli", "rbp.commands.plan")  # inside cmd_plan
    assert graph.has_edge("systems.reachbot_lcm", "systems.reachbot_lcm.rig_status_t")
    assert not graph.has_edge("planning.plan", "planning.footsteps")  # TYPE_CHECKING only
    assert len(graph) > 60 and graph.number_of_edges() > 150  # not vacuous


def test_no_module_imports_a_higher_layer(graph: nx.DiGraph) -> None:
    modules = module_files()
    upward = [f"{modules[a].relative_to(ROOT)}:{line}: {a} imports {b} "
              f"({LAYERS[layer(a)]} may not import {LAYERS[layer(b)]})"
              for a, b, line in sorted(graph.edges(data="line")) if layer(b) > layer(a)]
    assert not upward, ("imports from a higher layer (layers, lowest first: "
                        + " <- ".join(LAYERS) + "):\n" + "\n".join(upward))


def test_experiments_import_no_other_experiment(graph: nx.DiGraph) -> None:
    modules = module_files()
    wrong = [f"{modules[a].relative_to(ROOT)}:{line}: {a} imports the experiment {b}"
             for a, b, line in sorted(graph.edges(data="line"))
             if a.startswith("experiments.") and b.startswith("experiments")
             and b not in EXPERIMENT_LIBRARIES and experiment_of(a) != experiment_of(b)]
    assert not wrong, ("experiments import only " + ", ".join(sorted(EXPERIMENT_LIBRARIES))
                       + " of their layer:\n" + "\n".join(wrong))


def test_no_import_cycles(graph: nx.DiGraph) -> None:
    cycles = list(nx.simple_cycles(graph))
    lines = []
    for cycle in sorted(cycles, key=lambda c: (len(c), sorted(c))):
        steps = [f"{a} (line {graph.edges[a, b]['line']})"
                 for a, b in zip(cycle, [*cycle[1:], cycle[0]], strict=True)]
        lines.append(" -> ".join([*steps, cycle[0]]))
    assert not lines, "import cycles between modules:\n" + "\n".join(lines)


def test_architecture_names_existing_paths() -> None:
    """Every file or folder of the project that docs/architecture.md names exists."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    tops = "|".join(["tests", "docs", "lcmtypes", *LAYERS])
    named = set(re.findall(rf"`((?:{tops})/[\w./-]*)`", text))
    assert len(named) > 30, sorted(named)  # not vacuous
    missing = sorted(p for p in named if not (ROOT / p).exists())
    assert not missing, f"docs/architecture.md names paths that do not exist: {missing}"
