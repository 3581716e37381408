"""The package's import graph, read from the source (every import, those inside functions
too): no circle between modules, and the ground floor (core/) imports nothing above it, so
that each layer can be read, tested and reused from the floor up."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "sparse_body"


def _imports() -> dict[str, set[str]]:
    """Each module's imports of the package's own modules, by dotted name."""
    files = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph: dict[str, set[str]] = {}
    for module, path in files.items():
        here = module if path.name == "__init__.py" else module.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                base = here.split(".")[: len(here.split(".")) - node.level + 1] if node.level else []
                target = ".".join(base + ([node.module] if node.module else []))
                found |= {t for t in [target, *(f"{target}.{a.name}" for a in node.names)] if t in files}
            elif isinstance(node, ast.Import):
                found |= {a.name for a in node.names if a.name in files}
        graph[module] = found - {module}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan's algorithm)."""
    order: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []

    def visit(module: str) -> None:
        order[module] = low[module] = len(order)
        stack.append(module)
        for other in sorted(graph[module]):
            if other not in order:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in stack:
                low[module] = min(low[module], order[other])
        if low[module] == order[module]:
            group = []
            while (top := stack.pop()) != module:
                group.append(top)
            if group:
                circles.append(sorted([module, *group]))

    for module in sorted(graph):
        if module not in order:
            visit(module)
    return circles


def test_no_module_imports_itself_through_others():
    assert _circles(_imports()) == []


def test_the_circle_finder_finds_a_circle():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_core_imports_nothing_above_it():
    graph = _imports()
    upward = {m: sorted(t for t in graph[m] if not t.startswith("sparse_body.core")) for m in graph}
    assert {m: t for m, t in upward.items() if m.startswith("sparse_body.core") and t} == {}


# The floors, lowest first: a module imports only from its own floor or below. A method's
# runtime (estimator, options, features, ONNX runtimes) is its folder under methods/; its
# training side (torch model, trainer, card, the torch reference and bench) its folder under
# train/, with the harness it uses.
FLOORS = {
    "core": 0,
    "robot": 1,
    "adapters": 1,
    "io": 2,
    "data": 3,
    "estimators": 4,
    "methods": 5,
    "evaluation": 6,
    "train": 7,
    "ros": 8,
    "apps": 9,
    "cli": 10,
}


def _floor(module: str) -> int:
    parts = module.split(".")
    return 0 if len(parts) == 1 else FLOORS[parts[1]]  # (the package itself: its version)


def test_torch_is_imported_only_under_train():
    """What a node needs runs without torch: the training side of every method is under train/."""
    outside = []
    for path in PACKAGE.rglob("*.py"):
        if path.relative_to(PACKAGE).parts[0] == "train":
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            if any(n == "torch" or n.startswith("torch.") for n in names):
                outside.append(str(path.relative_to(PACKAGE)))
    assert outside == []


def test_no_arrow_runs_back_up_the_floors():
    graph = _imports()
    assert all(m.split(".")[1] in FLOORS for m in graph if "." in m), "a new top-level module: give it a floor"
    upward = sorted(f"{m} -> {t}" for m, targets in graph.items() for t in targets if _floor(t) > _floor(m))
    assert upward == []
