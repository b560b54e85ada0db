"""Damage a session file the ways disks and copies do, for the storage-damage tests and
``benchmarks/storage_damage.py``: flipped bits (anywhere, or inside one dataset's stored bytes), truncation.

Only ever applied to copies made for the purpose: these functions write into the file in place, bypassing the
recorder's copy-on-write on purpose.
"""

from __future__ import annotations

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


def dataset_span(path: Path, dataset: str) -> tuple[int, int]:
    """Byte range [start, stop) of a dataset's stored data in ``path`` (its first chunk when chunked)."""
    with h5py.File(path, "r") as f:
        ds = f[dataset]
        if ds.chunks is not None:
            info = ds.id.get_chunk_info(0)
            return int(info.byte_offset), int(info.byte_offset + info.size)
        offset = ds.id.get_offset()
        if offset is None:
            raise ValueError(f"{dataset} in {path} has no stored data")
        return int(offset), int(offset + ds.id.get_storage_size())


def flip_bits_in_dataset(path: Path, dataset: str, count: int, seed: int) -> list[int]:
    """Flip ``count`` bits inside the stored bytes of ``dataset`` (e.g. ``presses/rot000_ang+00/robot/t_s``):
    a plain array then reads back other values; a compressed chunk no longer decompresses."""
    return flip_bits(path, count, seed, dataset_span(path, dataset))


def press_ids(path: Path) -> list[str]:
    with h5py.File(path, "r") as f:
        return sorted(f["presses"])


RAW_PARTS = ("robot/", "tactile/", "tare_baseline", "events")


def raw_contents(path: Path) -> dict[str, str]:
    """press id -> digest of what was recorded in a session file (raw streams, tare, events, status): what damage
    may not lose. The extraction is left out (``extract`` recomputes it); an unreadable press is absent."""
    from unitac_rig.storage.checksums import array_digest, attrs_digest

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
