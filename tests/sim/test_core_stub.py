"""python/binpick/_core.pyi describes the native module exactly: the same functions and classes,
the same methods, the same parameter names in the same order. (Kept with the simulator's tests,
whose bindings are the largest part of the module.)"""

import ast
import inspect
import types
from pathlib import Path

import binpick
from binpick import _core

STUB = ast.parse((Path(binpick.__file__).parent / "_core.pyi").read_text(encoding="utf-8"))


def _public(names):
    return {n for n in names if not n.startswith("__")}


def _params(fn: ast.FunctionDef) -> list[str]:
    names = [a.arg for a in fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs]
    return [n for n in names if n not in ("self", "cls")]


def _native_params(obj) -> list[str]:
    sig = getattr(obj, "__text_signature__", None)
    assert sig, f"{obj!r} has no text signature"
    return [p for p in inspect.signature(obj).parameters if p not in ("self", "$self")]


def _is_property(fn: ast.FunctionDef) -> bool:
    return any(isinstance(d, ast.Name) and d.id == "property" for d in fn.decorator_list)


def test_the_stub_lists_exactly_the_native_names():
    declared = _public(n.name for n in STUB.body if isinstance(n, (ast.FunctionDef, ast.ClassDef)))
    constants = _public(n.target.id for n in STUB.body if isinstance(n, ast.AnnAssign))
    assert declared | constants == _public(dir(_core))


def test_functions_and_methods_have_the_native_parameters():
    for node in STUB.body:
        if isinstance(node, ast.FunctionDef):
            assert _params(node) == _native_params(getattr(_core, node.name)), node.name
        elif isinstance(node, ast.ClassDef):
            cls = getattr(_core, node.name)
            methods = {f.name: f for f in node.body if isinstance(f, ast.FunctionDef)}
            assert _public(methods) == _public(dir(cls)), node.name
            for name, fn in methods.items():
                if name == "__new__":
                    if cls.__text_signature__ is not None:
                        assert _params(fn) == _native_params(cls), node.name
                elif _is_property(fn):
                    assert isinstance(getattr(cls, name), (property, types.GetSetDescriptorType)), f"{node.name}.{name}"
                else:
                    assert _params(fn) == _native_params(getattr(cls, name)), f"{node.name}.{name}"
