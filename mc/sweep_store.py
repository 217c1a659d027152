"""The files of a parameter sweep: ``sweep.json`` (the manifest) and ``chunks/*.npz``.

Every file is written atomically (temporary file, fsync, ``os.replace``), so a killed run leaves
only whole files; a resume reads back the chunks whose metadata match this run (``mc.sweep``).
"""

import io
import json
import os
import re
from pathlib import Path

import numpy as np

from oaraim.mc.store import jsonable, writing

FORMAT_VERSION = 1
MANIFEST = "sweep.json"
CHUNK_DIR = "chunks"
#: a finished chunk file: CELLHASH_B0_NBLOCKS.npz
CHUNK_RE = re.compile(r"^([0-9a-f]{16})_(\d{10})_(\d{6})\.npz$")


def write_atomic(path: Path, data: bytes):
    """Write ``data`` to ``path`` so that a reader (or a resume after SIGKILL) sees either the
    whole new file or none: temporary file in the same folder, fsync, rename. An ``OSError``
    names ``path``."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with writing(path), open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)  # a failed write (a full disk) leaves no temporary file


def remove_partial_writes(folder: Path):
    """Delete the temporary files of ``write_atomic`` that a killed run left in ``folder``."""
    for f in folder.iterdir():
        if f.name.endswith(".tmp"):
            f.unlink(missing_ok=True)


def read_json_or_none(path: Path):
    """The JSON in ``path`` (a manifest, an identity), or None if it is missing or unreadable."""
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def chunk_name(cell_hash, b0, nblocks):
    """File name of the chunk of blocks ``b0 .. b0 + nblocks - 1`` of one cell."""
    return f"{cell_hash}_{b0:010d}_{nblocks:06d}.npz"


def chunk_bytes(meta: dict, parts: dict) -> bytes:
    """An ``.npz`` of a chunk's partials with its metadata (checked when read back)."""
    buf = io.BytesIO()
    np.savez(buf, __meta__=np.array(json.dumps(meta, sort_keys=True)), **parts)
    return buf.getvalue()


def read_chunk(path: Path, meta: dict, reducers):
    """The partials stored in ``path``, or None if it is not a whole file of this sweep."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if json.loads(str(z["__meta__"])) != meta:
                return None
            parts = {k: z[k] for k in z.files if k != "__meta__"}
    except Exception:  # noqa: BLE001 - unreadable: recompute it
        return None
    nb = meta["nblocks"]
    for i, r in enumerate(reducers):
        for field, template in r.empty(nb).items():  # a partial has the shapes of empty(nb)
            got = parts.get(f"r{i}.{field}")
            if got is None or got.shape != template.shape or got.dtype != template.dtype:
                return None
    return parts


def normalized(obj):
    """``obj`` as the JSON tree it is stored as (NumPy values plain, inf as text)."""
    return json.loads(json.dumps(jsonable(obj), sort_keys=True, allow_nan=False,
                                 default=str))


def differences(old, new, prefix=""):
    """Dotted paths where two JSON trees differ, with both values."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in sorted(set(old) | set(new)):
            p = f"{prefix}{k}"
            if k not in old:
                out.append(f"{p} (new: {json.dumps(new[k])})")
            elif k not in new:
                out.append(f"{p} (was {json.dumps(old[k])}, now absent)")
            else:
                out += differences(old[k], new[k], p + ".")
        return out
    if old != new:
        return [f"{prefix.rstrip('.') or 'value'} (was {json.dumps(old)}, now {json.dumps(new)})"]
    return []




def remove_if_nothing_finished(out_dir: Path):
    """After a failed run: remove ``chunks/`` and the manifest if no chunk file was finished
    (a run that failed on its first chunk, e.g. on a malformed input file, leaves no
    half-made sweep folder); finished chunks stay, with their manifest, for ``--resume``."""
    chunk_dir = out_dir / CHUNK_DIR
    try:
        if chunk_dir.is_dir():
            remove_partial_writes(chunk_dir)
            if any(CHUNK_RE.match(f.name) for f in chunk_dir.iterdir()):
                return
            chunk_dir.rmdir()
        (out_dir / MANIFEST).unlink(missing_ok=True)
    except OSError:
        pass  # the original error is the one to report


def prepare_out_dir(out_dir: Path, manifest: dict, resume: bool):
    """Check or write the manifest; clear chunk files of an earlier run unless resuming."""
    chunk_dir = out_dir / CHUNK_DIR
    chunk_dir.mkdir(parents=True, exist_ok=True)
    mpath = out_dir / MANIFEST
    old = read_json_or_none(mpath)
    remove_partial_writes(chunk_dir)
    if resume:
        has_chunks = any(CHUNK_RE.match(f.name) for f in chunk_dir.iterdir())
        if old is None and has_chunks:
            raise ValueError(f"{out_dir} holds chunk files but no readable {MANIFEST}, so they "
                             "cannot be checked against this run; pick another --out or drop "
                             "--resume to start afresh")
        if old is not None:
            for part in ("fingerprint", "engine"):
                diffs = differences(old.get(part), manifest[part])
                if diffs:
                    raise ValueError(
                        f"cannot resume into {out_dir}: it holds a run with different "
                        f"parameters: {'; '.join(diffs)}. --resume continues a run with the "
                        "same parameters only (a narrowed or changed axis is a new run): pick "
                        "another --out, or drop --resume to start afresh")
    else:
        for f in chunk_dir.iterdir():
            if CHUNK_RE.match(f.name):
                f.unlink()
    if old != manifest:
        write_atomic(mpath, (json.dumps(manifest, indent=2, sort_keys=True) + "\n").encode())

