"""Pooling dataset directories: every session of several ``--data`` directories, each (object, sensor) once.

A session's identity is its (object, sensor): the file name, the join and the learning side all key on it. Pooled
directories may hold the *same* session twice (a copy on a laptop and on the lab server): sessions of identical
content (root attributes and every press's checksums: :func:`unitac_rig.storage.reader.session_digest`, the same in
any storage layout) are one session. Two different sessions for one (object, sensor) are a conflict the tool refuses
to settle silently (which one is right? both are real presses), so pooling stops with an error naming both files.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from unitac_rig.errors import DataError
from unitac_rig.storage.manifest import publish_when_done, staging_for
from unitac_rig.storage.reader import SessionInfo, list_sessions, session_digest


@dataclass(frozen=True)
class PooledSession:
    info: SessionInfo
    source: Path  # the dataset directory it was taken from
    sha256: str  # session_digest: the content's SHA-256 (root attributes and every press's checksums)
    also_in: tuple[Path, ...] = ()  # other directories holding a copy of the same content

    def described(self) -> dict[str, Any]:
        """What every export says of the session: object, file, simulated, the object's shape and material (from
        its ``object_spec``, the material upper-case; None without one), content digest and source directory."""
        spec = self.info.attrs.get("object_spec")
        spec = spec if isinstance(spec, dict) else {}
        material = spec.get("material")
        return {
            "object": self.info.object_id,
            "file": self.info.path.name,
            "simulated": self.info.simulated,
            "shape": spec.get("shape"),
            "material": str(material).upper() if material is not None else None,
            "sha256": self.sha256,
            "source": str(self.source),
        }


def pool_sessions(data_dirs: Sequence[Path]) -> list[PooledSession]:
    """Every session of ``data_dirs`` once, sorted by (object, sensor); DataError on an identity conflict or when
    there is no session at all."""
    if not data_dirs:
        raise DataError("no dataset directory given")
    chosen: dict[tuple[str, str], PooledSession] = {}
    for data_dir in data_dirs:
        for info in list_sessions(Path(data_dir)):
            key = (info.object_id, info.sensor)
            digest = session_digest(info.path)
            first = chosen.get(key)
            if first is None:
                chosen[key] = PooledSession(info, Path(data_dir), digest)
            elif first.sha256 == digest:
                if info.path.resolve() != first.info.path.resolve():
                    chosen[key] = PooledSession(first.info, first.source, digest, (*first.also_in, Path(data_dir)))
            else:
                raise DataError(
                    f"two sources disagree on session {info.object_id}/{info.sensor}: {first.info.path} "
                    f"(sha256 {first.sha256[:12]}) and {info.path} (sha256 {digest[:12]}) hold different presses",
                    hint="pool only one of them, or record the repeat under another object id",
                )
    if not chosen:
        listed = ", ".join(str(d) for d in data_dirs)
        raise DataError(f"no session files (*__*.h5) in {listed}", hint="run `unitac-rig collect` first")
    return [chosen[key] for key in sorted(chosen)]


@contextlib.contextmanager
def pooled_export(data_dirs: Sequence[Path], out: Path) -> Iterator[tuple[list[PooledSession], Path]]:
    """Pool ``data_dirs`` and build an export of them in a hidden sibling of ``out`` (the block's folder), renamed
    into place when the block ends (:func:`unitac_rig.storage.manifest.publish_when_done`): ``out`` is complete or
    absent."""
    out = Path(out)
    pooled = pool_sessions([Path(d) for d in data_dirs])
    with publish_when_done(staging_for(out), out) as staging:
        yield pooled, staging
