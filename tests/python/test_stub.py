"""The type stub describes exactly the module's public names and members."""

import ast
import pathlib

import crumple


def stub_names():
    tree = ast.parse((pathlib.Path(crumple.__file__).parent / "__init__.pyi").read_text())
    top, members = set(), {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            top.add(node.name)
            members[node.name] = (
                {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
                | {n.target.id for n in node.body if isinstance(n, ast.AnnAssign)})
        elif isinstance(node, ast.FunctionDef):
            top.add(node.name)
    return top, members


def test_stub_matches_module():
    top, members = stub_names()
    assert top == set(crumple.__all__)
    for name in crumple.__all__:
        obj = getattr(crumple, name)
        if not isinstance(obj, type) or issubclass(obj, BaseException):
            continue
        public = {m for m in dir(obj) if not m.startswith("_")}
        declared = {m for m in members[name] if not m.startswith("_")}
        assert public == declared, name


def test_every_public_callable_has_a_docstring():
    for name in crumple.__all__:
        assert getattr(crumple, name).__doc__, name
