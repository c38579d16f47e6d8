"""Reading FE matrices from MatrixMarket (.mtx), MATLAB (.mat) and numpy (.npz) files: untrusted input.

Sizes are bounded before anything is read, npz files are opened without pickle, and every failure is one
:class:`~cappe.exceptions.ModelError` line naming the file and the entry that asked for it.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import scipy.io
import scipy.sparse as sps
from numpy.typing import NDArray
from scipy.io.matlab import MatReadError, matfile_version

from cappe.exceptions import ModelError

__all__ = ["MAX_MATRIX_BYTES", "MAX_MATRIX_SIZE", "MatrixSpec", "read_matrix"]

#: Largest matrix file read (a full sparse FE model of a machine bed is a few tens of MB).
MAX_MATRIX_BYTES = 512 * 2**20
#: Largest order of a matrix read from a file.
MAX_MATRIX_SIZE = 2_000_000
_SUFFIXES = (".mtx", ".mat", ".npz")

#: A file name, or ``{"file": name, "key": variable}`` (.mat and .npz hold several arrays).
MatrixSpec = str | Mapping[str, object]


def read_matrix(spec: object, base: Path | None, where: str, *, square: bool = True,
                ) -> sps.csr_array | NDArray[np.float64]:
    """One real (square) matrix from a file named by ``spec``, relative to ``base`` (the model file's folder).

    Parameters
    ----------
    spec : str or mapping
        ``"bed_K.mtx"`` or ``{"file": "bed.npz", "key": "K"}``; the key may be left out where the file holds
        one array (or one sparse matrix written by :func:`scipy.sparse.save_npz`).
    base : Path or None
        Folder relative paths start from (None: the working directory).
    where : str
        The model entry, for messages (``"model.yaml, flexible_bodies[0].stiffness"``).
    square : bool
        Require a square matrix (a recovery matrix is rectangular).

    Returns
    -------
    scipy.sparse.csr_array or ndarray, shape (n, n) or (n_rows, n)
        Sparse where the file stores it sparse, dense otherwise; float64.

    Raises
    ------
    ModelError
        The file is missing, too large, of an unknown kind or malformed, the key is absent, or the matrix is not
        a finite real square matrix.
    """
    if isinstance(spec, str):
        name, key = spec, None
    elif isinstance(spec, Mapping) and isinstance(spec.get("file"), str) and set(spec) <= {"file", "key"}:
        name, key = str(spec["file"]), spec.get("key")
        if key is not None and not isinstance(key, str):
            msg = f"matrix key must be a string; got {key!r} ({where}.key)"
            raise ModelError(msg)
    else:
        msg = f"a matrix is given as a file name or {{file: NAME, key: VARIABLE}}; got {spec!r} ({where})"
        raise ModelError(msg)
    path = Path(name)
    if not path.is_absolute() and base is not None:
        path = base / path
    suffix = path.suffix.lower()
    if suffix not in _SUFFIXES:
        msg = f"matrix file {name!r} must end in {', '.join(_SUFFIXES)}; got {suffix or 'no suffix'!r} ({where})"
        raise ModelError(msg)
    try:
        size = path.stat().st_size
    except OSError as exc:
        msg = f"cannot read matrix file {path}: {exc.strerror or exc} ({where})"
        raise ModelError(msg) from exc
    if size > MAX_MATRIX_BYTES:
        msg = f"matrix file {path} is larger than {MAX_MATRIX_BYTES // 2**20} MiB ({where})"
        raise ModelError(msg)
    try:
        if suffix == ".mtx":
            _no_key(key, where)
            info = scipy.io.mminfo(str(path))
            _check_shape((int(info[0]), int(info[1])), path, where, square)
            raw: object = scipy.io.mmread(str(path))
        elif suffix == ".mat":
            raw = _from_mat(path, key, where, square)
        else:
            raw = _from_npz(path, key, where, square)
    except ModelError:
        raise
    # scipy raises MatReadError for empty .mat files and EOFError or OSError for cut ones: all bad input
    except (OSError, ValueError, TypeError, KeyError, IndexError, EOFError, MatReadError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        msg = f"cannot read matrix file {path}: {reason} ({where})"
        raise ModelError(msg) from exc
    return _as_matrix(raw, path, where, square)


def _no_key(key: str | None, where: str) -> None:
    if key is not None:
        msg = f"a MatrixMarket file holds one matrix: leave out 'key' ({where}.key)"
        raise ModelError(msg)


def _from_mat(path: Path, key: str | None, where: str, square: bool) -> object:
    if matfile_version(str(path))[0] == 2:  # MATLAB v7.3 files are HDF5, which scipy does not read
        msg = f"matrix file {path} is a MATLAB v7.3 (HDF5) file: save it with save(..., '-v7') ({where})"
        raise ModelError(msg)
    entries = {entry[0]: entry[1] for entry in scipy.io.whosmat(str(path))}
    key = _choose(list(entries), key, path, where)
    shape = entries[key]
    _check_shape(tuple(int(v) for v in shape), path, where, square)
    return scipy.io.loadmat(str(path), variable_names=[key])[key]


def _from_npz(path: Path, key: str | None, where: str, square: bool) -> object:
    with np.load(path, allow_pickle=False) as data:
        names = list(data.files)
        if key is None and {"format", "data", "indices", "indptr", "shape"} <= set(names):
            _check_shape(tuple(int(v) for v in data["shape"]), path, where, square)
            return sps.load_npz(path)
        key = _choose(names, key, path, where)
        return np.asarray(data[key])


def _choose(names: list[str], key: str | None, path: Path, where: str) -> str:
    if key is None:
        if len(names) != 1:
            msg = f"matrix file {path} holds {', '.join(names) or 'nothing'}: name one with 'key' ({where})"
            raise ModelError(msg)
        return names[0]
    if key not in names:
        msg = f"matrix file {path} has no entry {key!r}; it holds {', '.join(names) or 'nothing'} ({where}.key)"
        raise ModelError(msg)
    return key


def _check_shape(shape: tuple[int, ...], path: Path, where: str, square: bool = True) -> None:
    if len(shape) != 2 or (square and shape[0] != shape[1]):
        msg = f"matrix in {path} must be {'square' if square else 'two-dimensional'}; got shape {shape} ({where})"
        raise ModelError(msg)
    if max(shape) > MAX_MATRIX_SIZE:
        msg = f"matrix in {path} has {max(shape)} rows or columns, beyond the {MAX_MATRIX_SIZE} cappe reads ({where})"
        raise ModelError(msg)


def _as_matrix(raw: object, path: Path, where: str, square: bool) -> sps.csr_array | NDArray[np.float64]:
    if sps.issparse(raw):
        out: sps.csr_array | NDArray[np.float64] = sps.csr_array(raw)
        values = out.data
    else:
        arr = np.asarray(raw)
        if arr.dtype == object or arr.dtype.kind not in "biuf":
            msg = f"matrix in {path} must hold real numbers; got {arr.dtype} ({where})"
            raise ModelError(msg)
        out = values = np.array(arr, dtype=np.float64)
    _check_shape(tuple(out.shape), path, where, square)
    if np.iscomplexobj(values):
        msg = f"matrix in {path} must be real; got complex entries ({where})"
        raise ModelError(msg)
    if sps.issparse(out):
        out = sps.csr_array(out, dtype=np.float64)
        values = out.data
    if not np.isfinite(values).all():
        msg = f"matrix in {path} has NaN or inf entries ({where})"
        raise ModelError(msg)
    return out
