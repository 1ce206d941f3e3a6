"""Files that must be safe to write and to read: a new file never overwrites an old one, and an exported program is
checked before torch loads it, so that no file the package loads runs code.

:func:`fresh_path` picks a free name beside an existing file (``trace.jsonl`` -> ``trace-1.jsonl``).

:func:`load_exported_program` reads a ``.pt2`` (``torch.export.save``) once into memory, checks it against an
allowlist (:func:`check_exported_archive`), and only then hands the same bytes to ``torch.export.load``. What
``torch.export.load`` would otherwise run or unpickle, and what the check refuses:

- members outside the known layout (an AOTInductor library, legacy pickled weight or constant files, anything
  else), a root other than one folder, or another archive format or version;
- a weight or constant flagged ``use_pickle`` (``torch.load(weights_only=False)``), a custom or opaque object
  constant (``torch._C._pickle_load_obj``, ``pickle.loads``);
- sample inputs that ``torch.load(weights_only=True)`` refuses (torch would retry them with ``weights_only=False``);
- guard code (Python source that ``.module()`` compiles and runs), nested graphs, custom objects, graph operators
  outside :data:`ALLOWED_OPERATORS` (a graph calls whatever attribute of ``torch`` its nodes name), and symbolic
  shape expressions outside a small grammar (``sympy.sympify`` evaluates them).

Only torch and the standard library are imported (the deploy node's light core).
"""

from __future__ import annotations

import io
import json
import logging
import os
import re
import zipfile
from pathlib import Path

import torch

__all__ = ["ALLOWED_OPERATORS", "ExportedFileError", "OutputPathError", "check_exported_archive", "check_output_path",
           "fresh_path", "load_exported_program"]


class OutputPathError(ValueError):
    """A path that a file cannot be written to; the message names it and why."""


class ExportedFileError(ValueError):
    """An exported program that is refused; the message names the file and the problem (nothing was loaded)."""


def check_output_path(path: str | Path, what: str = "file", *, new_folders: bool = False) -> Path:
    """Check, before any work, that a ``what`` can be written at ``path``: ``path`` is not a folder, its folder exists
    (with ``new_folders``: or the nearest folder above it that does, where the writer will make the rest), and a file
    can be created there (tried, then removed). Nothing is left behind.

    Raises:
        OutputPathError: One line naming the path and the problem.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputPathError(f"{path}: is a folder; name a {what} in it")
    if path.exists() and not os.access(path, os.W_OK):
        raise OutputPathError(f"{path}: the {what} is not writable")
    folder = path.parent
    if not folder.exists() and not new_folders:
        raise OutputPathError(f"{path}: the folder {folder} does not exist")
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise OutputPathError(f"{path}: {folder} is not a folder")
    probe = folder / f".{path.name}.{os.getpid()}.probe"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
        os.unlink(probe)
    except OSError as err:
        raise OutputPathError(f"{path}: cannot write in {folder} ({err.strerror or err})") from None
    return path


def fresh_path(path: str | Path) -> tuple[Path, str | None]:
    """Where to write a new file asked for at ``path`` without overwriting one: ``path`` if nothing is there, else
    the first free ``NAME-1.EXT``, ``NAME-2.EXT``…; and the line that says so (None where it is ``path``). The file
    is created empty, so that the name is taken.

    Raises:
        OutputPathError: The folder is missing or not a folder, ``path`` is a folder, or no file can be created
            there (the reason named).
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise OutputPathError(f"{path}: the folder {path.parent} does not exist (create it first)")
    if path.is_dir():
        raise OutputPathError(f"{path}: is a folder; name a file in it")
    candidate, k = path, 0
    while True:
        try:
            fd = os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            k += 1
            candidate = path.with_name(f"{path.stem}-{k}{path.suffix}")
            continue
        except OSError as err:
            raise OutputPathError(f"{path}: cannot be written ({err.strerror or err})") from None
        os.close(fd)
        return candidate, (None if candidate == path else f"{path} exists and is kept: writing {candidate}")


# ------------------------------------------------------------------ exported programs

ALLOWED_OPERATORS = frozenset({
    # arithmetic and activations
    "add", "sub", "rsub", "mul", "div", "neg", "abs", "exp", "log", "sqrt", "rsqrt", "pow", "reciprocal", "sign",
    "tanh", "sigmoid", "relu", "elu", "selu", "celu", "leaky_relu", "silu", "gelu", "mish", "softplus", "hardtanh",
    "clamp", "clamp_min", "clamp_max", "clip", "minimum", "maximum", "where", "softmax", "_softmax", "log_softmax",
    "_log_softmax",
    # linear algebra and normalisation
    "linear", "addmm", "mm", "bmm", "matmul", "t", "layer_norm", "native_layer_norm",
    "_native_batch_norm_legit_no_training", "batch_norm", "dropout",
    # shapes and copies
    "view", "reshape", "_unsafe_view", "slice", "select", "squeeze", "unsqueeze", "expand", "permute", "transpose",
    "flatten", "cat", "stack", "split", "split_with_sizes", "chunk", "narrow", "index_select", "alias", "clone",
    "contiguous", "detach", "_to_copy", "to", "full", "full_like", "zeros_like", "ones_like", "mean", "sum", "amax",
    "amin", "max", "min",
    # symbolic shapes
    "sym_size", "sym_numel", "_assert_scalar", "sym_constrain_range_for_size", "sym_constrain_range",
})
"""The ``torch.ops.aten`` operators (any overload) an exported policy's graph may call: the pure tensor maths of a
policy network. A graph node that names anything else (another namespace, a higher-order operator, an attribute of
``torch`` that is no operator) is refused."""

_PYTHON_OPERATORS = frozenset({"getitem", "add", "sub", "mul", "floordiv", "truediv", "mod", "neg", "eq", "ne", "ge",
                               "gt", "le", "lt", "and_", "or_", "not_"})
_ATEN = re.compile(r"torch\.ops\.aten\.([a-z_0-9]+)\.[A-Za-z_0-9]+")
_SYMBOL = re.compile(r"Symbol\('[a-z]{1,3}\d+'(, *(positive|integer|real|nonnegative|finite)=(True|False))*\)")
_SYMPY_NAMES = frozenset({"Max", "Min", "Eq", "Ne", "Le", "Lt", "Ge", "Gt", "And", "Or", "Not", "True", "False",
                          "Integer", "FloorDiv", "CeilDiv", "Mod", "PythonMod", "CleanDiv", "ModularIndexing",
                          "Where", "FloorToInt", "CeilToInt", "TruncToInt", "Identity"})
_EXPRESSION = re.compile(r"[A-Za-z0-9_+\-*/%(), <>=!]*")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_MEMBERS = re.compile(r"archive_format|archive_version|byteorder|\.data/version|\.data/serialization_id|"
                      r"models/model\.json|data/sample_inputs/model\.pt|data/weights/model_weights_config\.json|"
                      r"data/weights/weight_\d+|data/constants/model_constants_config\.json|"
                      r"data/constants/tensor_\d+|extra/[A-Za-z0-9_.\-]+")
_MODEL_KEYS = frozenset({"graph_module", "opset_version", "range_constraints", "schema_version", "verifiers",
                         "torch_version", "guards_code"})
_TREESPEC_TYPES = frozenset({None, "builtins.tuple", "builtins.list", "builtins.dict", "collections.OrderedDict"})
SCHEMA_MAJOR = 8
"""The ``torch.export`` schema's major version this check knows (torch 2.8 … 2.13 write it)."""


def _refuse(path, problem: str) -> ExportedFileError:
    return ExportedFileError(f"{path}: refused: {problem} (nothing in it was loaded)")


def _check_expression(path, text) -> None:
    if not isinstance(text, str):
        raise _refuse(path, f"a symbolic shape that is not text ({text!r})")
    rest = _SYMBOL.sub("s0", text)
    names = set(_NAME.findall(rest))
    bad = {n for n in names if n not in _SYMPY_NAMES and not re.fullmatch(r"[a-z]{1,3}\d+", n)}
    if not _EXPRESSION.fullmatch(rest) or bad or "__" in rest:
        raise _refuse(path, f"a symbolic shape expression outside the known grammar: {text[:80]!r}")


def _check_target(path, target) -> None:
    if not isinstance(target, str):
        raise _refuse(path, f"a graph node whose target is not a name ({target!r})")
    m = _ATEN.fullmatch(target)
    if m and m[1] in ALLOWED_OPERATORS:
        return
    if target.startswith("_operator.") and target.removeprefix("_operator.") in _PYTHON_OPERATORS:
        return
    raise _refuse(path, f"its graph calls {target!r}, which no atrv_warp policy uses (allowed: the aten operators "
                        "of atrv_warp.core.files.ALLOWED_OPERATORS)")


def _check_treespec(path, text) -> None:
    try:
        protocol, spec = json.loads(text)
    except (TypeError, ValueError):
        raise _refuse(path, "an input or output layout that is not JSON") from None

    def walk(node):
        if not isinstance(node, dict) or node.get("type") not in _TREESPEC_TYPES:
            raise _refuse(path, f"an input or output layout of type {node.get('type') if isinstance(node, dict) else node!r}")
        for child in node.get("children_spec", []):
            walk(child)

    if protocol != 1:
        raise _refuse(path, f"an input or output layout of protocol {protocol!r}")
    walk(spec)


def _check_model(path, model) -> None:
    if not isinstance(model, dict) or set(model) - _MODEL_KEYS:
        raise _refuse(path, f"a program description with unknown entries {sorted(set(model) - _MODEL_KEYS)}"
                      if isinstance(model, dict) else "a program description that is not a JSON object")
    major = (model.get("schema_version") or {}).get("major")
    if major != SCHEMA_MAJOR:
        raise _refuse(path, f"torch.export schema {major!r}; this reader knows schema {SCHEMA_MAJOR} (export the "
                            "policy again with a torch of 2.8 or later)")
    if model.get("guards_code"):
        raise _refuse(path, "it carries guard code (Python source that loading would compile and run)")
    graph = (model.get("graph_module") or {}).get("graph")
    if not isinstance(graph, dict) or not isinstance(graph.get("nodes"), list):
        raise _refuse(path, "a program description without a graph")
    if graph.get("custom_obj_values"):
        raise _refuse(path, "its graph holds custom objects")

    def walk(node):
        if isinstance(node, dict):
            for key, value in node.items():
                if key in ("as_graph", "as_custom_obj", "as_custom_objs"):
                    raise _refuse(path, f"its graph holds a {key.removeprefix('as_').replace('_', ' ')}")
                if key == "expr_str":
                    _check_expression(path, value)
                elif key in ("in_spec", "out_spec") and value is not None:
                    _check_treespec(path, value)
                elif key == "as_operator":
                    _check_target(path, value)
                else:
                    walk(value)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    for node in graph["nodes"]:
        _check_target(path, node.get("target") if isinstance(node, dict) else node)
    walk(model)


def _check_payloads(path, config, members: set[str], prefix: str) -> None:
    entries = (config or {}).get("config")
    if not isinstance(entries, dict):
        raise _refuse(path, f"a {prefix} table that is not a JSON object")
    for name, meta in entries.items():
        if not isinstance(meta, dict) or meta.get("use_pickle") is not False or meta.get("tensor_meta") is None:
            raise _refuse(path, f"the {prefix} {name!r} is not a plain tensor (pickled, or a custom or opaque object)")
        file = meta.get("path_name", "")
        if not re.fullmatch(rf"{prefix}_\d+", str(file)) or file not in members:
            raise _refuse(path, f"the {prefix} {name!r} points at {file!r}, which is not a {prefix} file of the archive")


def check_exported_archive(data: bytes, path: str | Path = "<bytes>") -> dict[str, str]:
    """Check a ``.pt2``'s bytes against the allowlist (module docstring) without loading anything through torch but
    its sample inputs, with ``torch.load(weights_only=True)``; returns its extra files (name -> text).

    Raises:
        ExportedFileError: The first thing refused, named.
    """
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        names = archive.namelist()
    except (zipfile.BadZipFile, ValueError, OSError) as err:
        raise ExportedFileError(f"{path}: not an exported policy (not a torch.export archive: {err})") from None
    roots = {n.split("/", 1)[0] for n in names}
    if len(roots) != 1 or any("/" not in n for n in names):
        raise _refuse(path, f"an archive with {len(roots)} top-level entries (torch.export writes one folder)")
    root = roots.pop() + "/"
    members = {n[len(root):] for n in names}
    odd = sorted(m for m in members if not _MEMBERS.fullmatch(m))
    if odd:
        raise _refuse(path, f"unknown archive member(s) {odd[:4]} (an exported policy holds a program, its weights "
                            "and extra text files only)")

    def text(member: str) -> str:
        try:
            return archive.read(root + member).decode()
        except KeyError:
            raise _refuse(path, f"no {member} in the archive") from None
        except (UnicodeDecodeError, zipfile.BadZipFile, OSError, RuntimeError) as err:
            raise _refuse(path, f"an unreadable {member} ({err})") from None

    def json_of(member: str):
        try:
            return json.loads(text(member))
        except json.JSONDecodeError:
            raise _refuse(path, f"{member} is not JSON") from None

    if text("archive_format") != "pt2" or text("archive_version") != "0":
        raise _refuse(path, f"archive format {text('archive_format')!r} version {text('archive_version')!r} (this "
                            "reader knows 'pt2' version '0')")
    weights = {m.rsplit("/", 1)[1] for m in members if m.startswith("data/weights/weight_")}
    constants = {m.rsplit("/", 1)[1] for m in members if m.startswith("data/constants/tensor_")}
    _check_payloads(path, json_of("data/weights/model_weights_config.json"), weights, "weight")
    _check_payloads(path, json_of("data/constants/model_constants_config.json"), constants, "tensor")
    _check_model(path, json_of("models/model.json"))
    try:
        sample = torch.load(io.BytesIO(archive.read(root + "data/sample_inputs/model.pt")), weights_only=True)
    except KeyError:
        raise _refuse(path, "no sample inputs") from None
    except Exception as err:  # noqa: BLE001 - torch refuses a pickled object in many ways; all are a refusal
        raise _refuse(path, f"its sample inputs hold more than tensors ({' '.join(str(err).split())[:120]})") from None
    if not isinstance(sample, (tuple, dict)):
        raise _refuse(path, f"its sample inputs are a {type(sample).__name__}")
    return {m.removeprefix("extra/"): text(m) for m in sorted(members) if m.startswith("extra/")}


def load_exported_program(path: str | Path) -> tuple[torch.export.ExportedProgram, dict[str, str]]:
    """A ``.pt2``, checked (:func:`check_exported_archive`) and loaded from the bytes that were checked; and its
    extra files (name -> text).

    Raises:
        FileNotFoundError: No such file.
        ExportedFileError: Refused by the check, or ``torch.export.load`` failed on what passed it (named).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    data = path.read_bytes()
    extra = check_exported_archive(data, path)
    wanted = dict.fromkeys(extra, "")
    quiet = logging.getLogger("torch.export")  # it logs a traceback of its own before raising
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)
    try:
        program = torch.export.load(io.BytesIO(data), extra_files=wanted)
    except Exception as err:  # noqa: BLE001 - torch raises many kinds (schema, shapes) on a damaged program
        raise ExportedFileError(f"{path}: not a loadable exported policy (torch.export.load: {type(err).__name__}: "
                                f"{' '.join(str(err).split())[:160]})") from None
    finally:
        quiet.setLevel(level)
    return program, extra
