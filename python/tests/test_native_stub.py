"""The hand-written stub `_native.pyi` matches the compiled module: the same functions,
methods and properties, and every function's parameters by name, kind and default."""

import ast
import inspect
import pathlib

import doma
from doma import _native

STUB = pathlib.Path(doma.__file__).with_name("_native.pyi")


def _stub() -> ast.Module:
    return ast.parse(STUB.read_text())


def _parameters(node: ast.FunctionDef) -> list[tuple[str, str]]:
    """(name, kind) of a stub function's parameters, `self` left out."""
    a = node.args
    out = [(p.arg, "POSITIONAL_OR_KEYWORD") for p in a.posonlyargs + a.args if p.arg != "self"]
    if a.vararg:
        out.append((a.vararg.arg, "VAR_POSITIONAL"))
    out += [(p.arg, "KEYWORD_ONLY") for p in a.kwonlyargs]
    if a.kwarg:
        out.append((a.kwarg.arg, "VAR_KEYWORD"))
    return out


def _native_parameters(function) -> list[tuple[str, str]]:
    kinds = {"POSITIONAL_ONLY": "POSITIONAL_OR_KEYWORD"}
    return [
        (p.name, kinds.get(p.kind.name, p.kind.name))
        for p in inspect.signature(function).parameters.values()
        if p.name != "self"
    ]


def test_every_function_of_the_module_is_in_the_stub_with_its_parameters():
    stub = {n.name: n for n in _stub().body if isinstance(n, ast.FunctionDef)}
    native = {
        name for name, value in vars(_native).items() if callable(value) and not isinstance(value, type)
    }
    assert set(stub) == native
    for name in native:
        assert _parameters(stub[name]) == _native_parameters(getattr(_native, name)), name


def test_the_field_class_in_the_stub_has_every_method_and_property():
    (cls,) = [n for n in _stub().body if isinstance(n, ast.ClassDef) and n.name == "Field"]
    stub = {n.name: n for n in cls.body if isinstance(n, ast.FunctionDef)}
    native = {name for name in vars(_native.Field) if not name.startswith("__")}
    assert set(stub) == native
    for name in native:
        value = getattr(_native.Field, name)
        if callable(value):
            assert _parameters(stub[name]) == _native_parameters(value), name


def test_the_stub_names_every_module_constant():
    assigned = {n.target.id for n in _stub().body if isinstance(n, ast.AnnAssign)}
    constants = {name for name, value in vars(_native).items() if not callable(value) and not name.startswith("__")}
    assert constants <= assigned | {"__version__"}
    assert "__version__" in assigned
