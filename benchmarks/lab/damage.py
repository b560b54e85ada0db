"""Damage a session the ways disks and copies do, for the storage-damage tests and
``benchmarks/storage_damage.py``: flipped bits (anywhere, or inside one dataset's stored bytes), truncation.

Only ever applied to copies made for the purpose: these functions write into the file in place, bypassing the
recorder's copy-on-write on purpose.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import h5py
import numpy as np


def flip_bits(path: Path, count: int, seed: int, span: tuple[int, int] | None = None) -> list[int]:
    """Flip ``count`` distinct random bits of ``path`` (within byte ``span`` [start, stop) when given); returns the
    bit positions flipped (byte * 8 + bit). Seeded: the same call damages the same bits."""
    path = Path(path)
    data = bytearray(path.read_bytes())
    start, stop = span if span is not None else (0, len(data))
    rng = np.random.default_rng(seed)
    bits = rng.choice((stop - start) * 8, size=min(count, (stop - start) * 8), replace=False)
    positions = sorted(int(start * 8 + b) for b in bits)
    for pos in positions:
        data[pos // 8] ^= 1 << (pos % 8)
    path.write_bytes(bytes(data))
    return positions


def dataset_location(path: Path, dataset: str) -> tuple[Path, tuple[int, int]]:
    """The file that stores ``dataset`` (``path`` itself, or the press file a session file links the press to) and
    the byte range [start, stop) of its stored data in that file (its first chunk when chunked)."""
    with h5py.File(path, "r") as f:
        ds = f[dataset]
        holder = Path(ds.file.filename)
        if ds.chunks is not None:
            info = ds.id.get_chunk_info(0)
            return holder, (int(info.byte_offset), int(info.byte_offset + info.size))
        offset = ds.id.get_offset()
        if offset is None:
            raise ValueError(f"{dataset} in {path} has no stored data")
        return holder, (int(offset), int(offset + ds.id.get_storage_size()))


def flip_bits_in_dataset(path: Path, dataset: str, count: int, seed: int) -> list[int]:
    """Flip ``count`` bits inside the stored bytes of ``dataset`` (e.g. ``presses/rot000_ang+00/robot/t_s``), in
    the file that stores them (a session's press file when the session file links it): a plain array then reads
    back other values; a compressed chunk no longer decompresses."""
    holder, span = dataset_location(path, dataset)
    return flip_bits(holder, count, seed, span)


def press_ids(path: Path) -> list[str]:
    with h5py.File(path, "r") as f:
        return sorted(f["presses"])


RAW_PARTS = ("robot/", "tactile/", "tare_baseline", "events")


def raw_contents(path: Path) -> dict[str, str]:
    """press id -> digest of what was recorded in a session file (raw streams, tare, events, status): what damage
    may not lose. The extraction is left out (``extract`` recomputes it); an unreadable press is absent."""
    from unitac_rig.storage.integrity import array_digest, attrs_digest

    out: dict[str, str] = {}
    try:
        f = h5py.File(path, "r")
    except OSError:
        return out
    with f:
        try:
            names = sorted(f["presses"])
        except Exception:
            return out
        for pid in names:
            try:
                g = f["presses"][pid]
                parts = [f"{name}={array_digest(g[name][()])}" for name in _datasets(g) if name.startswith(RAW_PARTS)]
                out[pid] = attrs_digest([("status", g.attrs["status"]), ("arrays", parts)])
            except Exception:
                continue
    return out


def _datasets(group: h5py.Group) -> list[str]:
    names: list[str] = []
    group.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
    return sorted(names)


# -- a press intact but in the wrong place, and the journal's own damage (issue 41) ---------------------------------
# Each takes a dataset folder and the (object, sensor) session to damage; what it returns names what it changed.


def _press_file(data: Path, object_id: str, sensor: str, pid: str) -> Path:
    """The press file the session file of (object, sensor) links ``pid`` to."""
    session = Path(data) / f"{object_id}__{sensor}.h5"
    with h5py.File(session, "r") as f:
        link = f["presses"].get(pid, getlink=True)
    return session.parent / str(link.filename)


def copy_press_over(data: Path, source: tuple[str, str], target: tuple[str, str], index: int = 0) -> str:
    """Copy ``source``'s press file of a press id both sessions have over ``target``'s file of that press (another
    object's press, or another sensor's): intact bytes in the wrong place. Returns the press id."""
    shared = sorted(
        set(press_ids(Path(data) / f"{source[0]}__{source[1]}.h5"))
        & set(press_ids(Path(data) / f"{target[0]}__{target[1]}.h5"))
    )
    pid = shared[index]
    shutil.copyfile(_press_file(data, *source, pid), _press_file(data, *target, pid))
    return pid


def swap_press_files(data: Path, object_id: str, sensor: str, first: int = 0, second: int = 1) -> tuple[str, str]:
    """Swap the contents of two press files of one session (their names stay)."""
    pids = press_ids(Path(data) / f"{object_id}__{sensor}.h5")
    a, b = _press_file(data, object_id, sensor, pids[first]), _press_file(data, object_id, sensor, pids[second])
    _swap(a, b)
    return pids[first], pids[second]


def swap_journal_entries(data: Path, object_id: str, sensor: str, first: int = 0, second: int = 1) -> tuple[str, str]:
    """Swap the contents of two journal entries of one session (their names stay)."""
    journal = Path(data) / ".journal" / f"{object_id}__{sensor}"
    pids = press_ids(Path(data) / f"{object_id}__{sensor}.h5")
    _swap(journal / f"{pids[first]}.h5", journal / f"{pids[second]}.h5")
    return pids[first], pids[second]


def delete_press_file(data: Path, object_id: str, sensor: str, index: int = 0) -> str:
    pid = press_ids(Path(data) / f"{object_id}__{sensor}.h5")[index]
    _press_file(data, object_id, sensor, pid).unlink()
    return pid


def flip_seal_name(path: Path, bit: int = 4) -> int:
    """Flip one bit inside the stored name ``attrs_sha256`` of a session file's root seal: the attribute area is
    damaged so that the seal reads as absent (the review's "offset 7792 bit 4"). Returns the byte offset."""
    raw = bytearray(Path(path).read_bytes())
    offset = raw.find(b"attrs_sha256")
    if offset < 0:
        raise ValueError(f"{path} has no root seal to damage")
    offset += 3
    raw[offset] ^= 1 << bit
    Path(path).write_bytes(bytes(raw))
    return offset


def _swap(a: Path, b: Path) -> None:
    tmp = a.with_name(a.name + ".swap")
    os.replace(a, tmp)
    os.replace(b, a)
    os.replace(tmp, b)
