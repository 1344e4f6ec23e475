"""The package's architecture, read from its source: no import circle, imports flowing
downstream only (data -> signal -> models -> calibration -> studies -> diagnosis ->
plotting / CLI), no module importing another folder's private names.

The graph is built from the source text (`ast`), so the tests see every import, also the
ones deferred into a function body; only imports under `if TYPE_CHECKING:` are left out
(they never run). A module importing `jaxvs.a.b` also runs the `__init__.py` of
`jaxvs.a` and `jaxvs.a.b`, so an edge to a module is an edge to every package above it
(except the packages the importing module already lives in, which are being imported).
"""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1] / "jaxvs"

# Where each folder stands in the flow of the data; a module may import its own layer and
# those before it. The modules at the top of the package (`jaxvs/_misc.py`, `_io.py`, ...)
# are the shared low level every folder may use; `twins` builds plants from `models`;
# the command line (`_cli.py`, `_demo.py`) sits after plotting, `jaxvs/__init__.py` last.
LAYERS = {
    "jaxvs._shared": 0,
    "jaxvs.data": 1,
    "jaxvs.signal": 2,
    "jaxvs.models": 3,
    "jaxvs.twins": 3.5,
    "jaxvs.calibration": 4,
    "jaxvs.studies": 5,
    "jaxvs.diagnosis": 6,
    "jaxvs.plotting": 7,
    "jaxvs._cli": 8,
    "jaxvs._demo": 8,
    "jaxvs": 9,
}

# Only the demo of the command line runs the twins (the plants with hidden effects);
# the library itself never depends on them.
TWIN_USERS = {"jaxvs._demo"}

# Deferred imports that close a circle on purpose, each with its reason. The list may
# only shrink.
LATE_BINDINGS = {
    # A linear model's `predict` is the exact-discretisation engine and its dense form
    # a `StateSpace`; both are built on the model interface, so the interface looks
    # them up when it is called.
    ("jaxvs.models._base", "jaxvs.models._simulate"),
    ("jaxvs.models._base", "jaxvs.models.lti"),
}


class _Module:
    def __init__(self, name: str, path: pathlib.Path):
        self.name, self.path = name, path
        self.is_package = path.name == "__init__.py"
        self.package = name if self.is_package else name.rpartition(".")[0]
        self.tree = ast.parse(path.read_text(encoding="utf-8"), str(path))


def _modules() -> dict[str, _Module]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = _Module(".".join(parts), path)
    return out


MODULES = _modules()


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return skip


def _imports(module: _Module):
    """`(target module, imported names, line, deferred)` of every jaxvs import."""
    deferred = {
        id(n)
        for f in ast.walk(module.tree)
        if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)
        for n in ast.walk(f)
    }
    skip = _type_checking_nodes(module.tree)
    for node in ast.walk(module.tree):
        if id(node) in skip:
            continue
        late = id(node) in deferred
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "jaxvs":
                    yield alias.name, [], node.lineno, late
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "jaxvs":
                continue
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                if sub in MODULES:  # `from . import name` imports a module
                    yield sub, [], node.lineno, late
                else:
                    yield target, [alias.name], node.lineno, late


def _with_parents(importer: str, target: str) -> set[str]:
    """`target` and every package above it that `importer` does not already live in."""
    parts = target.split(".")
    out = set()
    for i in range(1, len(parts) + 1):
        name = ".".join(parts[:i])
        if name in MODULES and not (importer == name or importer.startswith(name + ".")):
            out.add(name)
    return out


def _graph(*, late_bindings=frozenset()) -> dict[str, set[str]]:
    graph = {}
    for name, module in MODULES.items():
        edges = set()
        for target, _, _, late in _imports(module):
            if target in MODULES and not (late and (name, target) in late_bindings):
                edges |= _with_parents(name, target)
        graph[name] = edges - {name}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.append(w)
                        if w == v:
                            break
                    if len(component) > 1:
                        out.append(sorted(component))
    return out


def _layer(name: str) -> float:
    parts = name.split(".")
    if len(parts) == 1:
        return LAYERS["jaxvs"]
    if parts[1] in ("_cli", "_demo"):
        return LAYERS[".".join(parts[:2])]
    key = ".".join(parts[:2])
    return LAYERS.get(key, LAYERS["jaxvs._shared"])


def _folder(name: str) -> str:
    module = MODULES[name]
    return module.package if not module.is_package else name


def test_the_graph_sees_the_package():
    # The parser resolves relative imports: the models' interface is imported by the
    # linear models (a test of the test, so that an empty graph cannot pass).
    graph = _graph()
    assert "jaxvs.models._base" in graph["jaxvs.models.lti._statespace"]
    calibrate = graph["jaxvs.calibration._calibrate"]
    assert {"jaxvs._misc", "jaxvs.calibration._parametrise"} <= calibrate
    assert "jaxvs.data" in graph["jaxvs.calibration._lscf"]  # a package, deferred
    assert len(MODULES) > 100


def test_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]


def test_no_import_circle():
    cycles = _cycles(_graph(late_bindings=LATE_BINDINGS))
    assert not cycles, "import circles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_late_bindings_are_still_needed():
    # Every allowed deferred import still exists and still closes a circle; otherwise it
    # must leave the list.
    full = _cycles(_graph())
    in_circle = {m for c in full for m in c}
    stale = [pair for pair in LATE_BINDINGS if not set(pair) <= in_circle]
    assert not stale, f"remove from LATE_BINDINGS: {stale}"


def test_imports_flow_downstream():
    wrong = []
    for name, edges in _graph().items():
        for target in edges:
            if _layer(target) > _layer(name):
                wrong.append(f"{name} imports {target}")
            if target.startswith("jaxvs.twins") and not (
                name.startswith("jaxvs.twins") or name in TWIN_USERS
            ):
                wrong.append(f"{name} imports the twins ({target})")
    assert not wrong, "upstream imports:\n" + "\n".join(sorted(wrong))


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_private_name_of_another_folder(name):
    # A private module (`_name.py`) may be imported from its own folder and from the
    # folders below it (`jaxvs/_misc.py` serves the whole package); a private name
    # (`_helper`) only from its own folder.
    folder = _folder(name)
    wrong = []
    for target, names, line, _ in _imports(MODULES[name]):
        parts = target.split(".")
        private_at = [i for i, p in enumerate(parts) if p.startswith("_")]
        if private_at:
            owner = ".".join(parts[: private_at[0]])
            if not (folder == owner or folder.startswith(owner + ".")):
                wrong.append(f"line {line}: {target}")
        target_folder = _folder(target) if target in MODULES else target
        for n in names:
            if n.startswith("_") and not n.startswith("__") and target_folder != folder:
                wrong.append(f"line {line}: {n} from {target}")
    assert not wrong, f"{name} reaches into private names:\n" + "\n".join(wrong)


# ----------------------------------------------------------------------------- arguments

MAX_ARGUMENTS = 10

# Functions allowed more than MAX_ARGUMENTS arguments (`self` not counted, `*args` and
# `**kwargs` one each), as "module:qualified name".
LONG_SIGNATURES = {
    # Public entry points that mirror a command line: one keyword per option of the command.
    "jaxvs.diagnosis._diagnose:diagnose",  # jaxvs diagnose
    "jaxvs.studies.design._design:design",  # jaxvs design
    "jaxvs.calibration._calibrate:calibrate",  # shaped like optimistix.least_squares
    # Pending: diagnosis internals, rebuilt in their own change.
}


def _signatures():
    """`(module:qualname, number of arguments)` of every function of the package."""
    for name, module in MODULES.items():
        stack = [(node, "") for node in module.tree.body]
        while stack:
            node, prefix = stack.pop()
            if isinstance(node, ast.ClassDef):
                stack += [(child, f"{prefix}{node.name}.") for child in node.body]
            elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                a = node.args
                names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
                if prefix and names[:1] in (["self"], ["cls"]):
                    names = names[1:]
                count = len(names) + (a.vararg is not None) + (a.kwarg is not None)
                yield f"{name}:{prefix}{node.name}", count
                stack += [(child, f"{prefix}{node.name}.") for child in node.body]


def test_no_long_argument_lists():
    # Long lists of options go into an options object (`jaxvs.signal.Welch`,
    # `jaxvs.studies.TMFFit`), whose fields stay accepted as keywords.
    counts = dict(_signatures())
    long = {k for k, n in counts.items() if n > MAX_ARGUMENTS}
    new = sorted(f"{k} ({counts[k]})" for k in long - LONG_SIGNATURES)
    assert not new, "more than 10 arguments; use an options object:\n" + "\n".join(new)
    gone = sorted(LONG_SIGNATURES - long)
    assert not gone, f"remove from LONG_SIGNATURES (now short or gone): {gone}"


# ----------------------------------------------------------------------------- length

MAX_DIAGNOSIS_LINES = 150

# Diagnosis functions allowed more than MAX_DIAGNOSIS_LINES lines, as "module:qualified
# name". The list may only shrink (a listed function may already be shorter).
LONG_FUNCTIONS = {
    # being split
    "jaxvs.diagnosis._diagnose:diagnose",
    "jaxvs.diagnosis._report:DiagnosisReport.to_markdown",
}


def _lengths(prefix: str):
    """`(module:qualified name, number of lines)` of every function of the modules under
    `prefix` (decorators and docstring included)."""
    for name, module in MODULES.items():
        if not (name == prefix or name.startswith(prefix + ".")):
            continue
        stack = [(node, "") for node in module.tree.body]
        while stack:
            node, qual = stack.pop()
            if isinstance(node, ast.ClassDef):
                stack += [(child, f"{qual}{node.name}.") for child in node.body]
            elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                yield f"{name}:{qual}{node.name}", node.end_lineno - node.lineno + 1
                stack += [(child, f"{qual}{node.name}.") for child in node.body]


def test_no_long_diagnosis_functions():
    lengths = dict(_lengths("jaxvs.diagnosis"))
    assert "jaxvs.diagnosis._diagnose:diagnose" in lengths  # the walk sees the package
    long = {k for k, n in lengths.items() if n > MAX_DIAGNOSIS_LINES}
    new = sorted(f"{k} ({lengths[k]} lines)" for k in long - LONG_FUNCTIONS)
    assert not new, f"over {MAX_DIAGNOSIS_LINES} lines; split them:\n" + "\n".join(new)
