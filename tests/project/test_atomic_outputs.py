"""Every output of the package goes through vtsbench.atomic (complete or absent, never half
written): a module that writes a file by other means fails here.

The scan looks at calls that write files (open in a writing mode, Path.write_text/write_bytes,
savefig, numpy's save functions, json.dump, safetensors' save_file, torch.save, cv2.imwrite,
tofile, a zipfile opened for writing, os.replace/rename). A call that writes into an in-memory
buffer (a name bound to io.BytesIO() in the same module) or onto a temporary path from
`atomic.replacing` is fine. ALLOWED lists the few other places, each with its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

import vtsbench

ROOT = Path(vtsbench.__file__).parent
HELPER = "atomic.py"

#: (module path, function) -> why that write does not go through the helper.
ALLOWED = {
    ("dataset/build/staging.py", "locked_stage"):
        "opens the lock file in append mode to hold a lock on it; writes nothing",
    ("dataset/read/location.py", "checked"):
        "copies a remote file into a private temporary folder to parse it; not an output",
    ("dataset/tools/hub_write.py", "write_kind"):
        "streams row groups into a hidden temporary file (too large for memory) and renames "
        "it when complete: atomic, by the same temporary-name rule",
}

WRITERS = {"write_text", "write_bytes", "savefig", "save", "savez", "savez_compressed", "dump",
           "save_file", "imwrite", "imsave", "tofile", "replace", "rename", "ParquetWriter"}


def _mode(call: ast.Call) -> str:
    """The mode of an open() call ('r' when not given or not a constant)."""
    args = call.args[1:2] + [k.value for k in call.keywords if k.arg == "mode"]
    if args and isinstance(args[0], ast.Constant) and isinstance(args[0].value, str):
        return args[0].value
    return "r"


def _memory_names(tree: ast.Module) -> set[str]:
    """Names bound to an in-memory buffer (io.BytesIO(), BytesIO()) or to the temporary path
    of `with replacing(...) as name`."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
            f = node.value.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if name in {"BytesIO", "StringIO"}:
                out.update(t.id for t in node.targets if isinstance(t, ast.Name))
        if isinstance(node, ast.With):
            for item in node.items:
                f = item.context_expr.func if isinstance(item.context_expr, ast.Call) else None
                name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                if name == "replacing" and isinstance(item.optional_vars, ast.Name):
                    out.add(item.optional_vars.id)
    return out


def _target(call: ast.Call) -> ast.expr | None:
    """The file a write call names: its first argument (`str(x)` counts as x), or for
    save_file (tensors, filename) the second."""
    args = call.args
    f = call.func
    name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
    target = (args[1] if len(args) > 1 else None) if name == "save_file" else \
        (args[0] if args else None)
    if isinstance(target, ast.Call) and getattr(target.func, "id", "") == "str" and target.args:
        return target.args[0]
    return target


def direct_writes(path: Path) -> list[tuple[str, int, str]]:
    """(function, line, what) of each file write in a module outside the helper."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    memory = _memory_names(tree)
    found = []

    def visit(node: ast.AST, func: str) -> None:
        for child in ast.iter_child_nodes(node):
            name = child.name if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef) \
                else func
            if isinstance(child, ast.Call):
                what = _write_of(child, memory)
                if what:
                    found.append((func, child.lineno, what))
            visit(child, name)

    visit(tree, "<module>")
    return found


def _write_of(call: ast.Call, memory: set[str]) -> str | None:
    f = call.func
    name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
    target = _target(call)
    into_memory = isinstance(target, ast.Name) and target.id in memory
    if name in {"open", "ZipFile"} and any(c in _mode(call) for c in "wax+"):
        return None if into_memory else f"{name}(..., {_mode(call)!r})"
    if name not in WRITERS:
        return None
    owner = f.value if isinstance(f, ast.Attribute) else None
    owner_name = owner.id if isinstance(owner, ast.Name) else ""
    if name in {"replace", "rename"}:  # only os.replace / os.rename / Path.replace of a path
        if owner_name != "os":
            return None
    elif (name in {"save", "savez", "savez_compressed"}
          and owner_name not in {"np", "numpy", "torch"}) or (name == "dump"
                                                               and owner_name != "json"):
        return None
    return None if into_memory else f"{owner_name + '.' if owner_name else ''}{name}()"


def test_every_output_goes_through_the_atomic_helper() -> None:
    bad = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel == HELPER:
            continue
        for func, line, what in direct_writes(path):
            if (rel, func) not in ALLOWED:
                bad.append(f"vtsbench/{rel}:{line} ({func}): {what}")
    assert not bad, "outputs written without vtsbench.atomic:\n" + "\n".join(bad)


def test_the_scan_finds_a_direct_write(tmp_path: Path) -> None:
    """The scan is not blind: each kind of direct write is found, a buffer write is not."""
    src = tmp_path / "m.py"
    src.write_text(
        "import io, json, os\nimport numpy as np\n"
        "def f(p, fig, doc):\n"
        "    p.write_text('x')\n"
        "    open(p, 'w').write('x')\n"
        "    fig.savefig(p)\n"
        "    np.save(p, 1)\n"
        "    json.dump(doc, open(p, 'wb'))\n"
        "    os.replace(p, p)\n"
        "    buf = io.BytesIO()\n"
        "    fig.savefig(buf)\n"
        "    np.save(buf, 1)\n"
        "    open(p).read()\n")
    found = [what for _f, _line, what in direct_writes(src)]
    assert found == ["p.write_text()", "open(..., 'w')", "fig.savefig()", "np.save()",
                     "json.dump()", "open(..., 'wb')", "os.replace()"]


def test_allowed_entries_still_exist() -> None:
    """An allow-list entry whose write is gone is removed, not kept as a blanket pass."""
    for rel, func in ALLOWED:
        assert any(f == func for f, _l, _w in direct_writes(ROOT / rel)), (rel, func)
