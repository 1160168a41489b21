"""The hand-written _core.pyi stays in sync with the extension."""

import ast
import inspect
from pathlib import Path

import sfanav
from sfanav import _core

STUB = Path(sfanav.__file__).with_name("_core.pyi")


def _stub_names():
    tree = ast.parse(STUB.read_text())
    top, classes = set(), {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            top.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            top.add(node.target.id)
        elif isinstance(node, ast.ClassDef):
            top.add(node.name)
            classes[node.name] = {
                n.name for n in node.body if isinstance(n, ast.FunctionDef) and not n.name.startswith("__")
            }
    return top, classes


def test_stub_matches_module():
    top, classes = _stub_names()
    public = {n for n in dir(_core) if not n.startswith("_")} | {"__version__"}
    assert top - {"FloatArray"} == public
    for cls, methods in classes.items():
        actual = {n for n in dir(getattr(_core, cls)) if not n.startswith("_")}
        assert methods == actual, cls


def test_py_typed_is_shipped():
    assert STUB.with_name("py.typed").exists()
