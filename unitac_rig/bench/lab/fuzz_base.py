"""The fuzz campaign's building blocks (see unitac_rig/bench/lab/fuzz.py): one input (:class:`Case`), what a target
did with its inputs (:class:`Report`), the :class:`Target` interface, and the input generators every target shares."""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from protocols.errors import ProtocolError

HANG_MS = 50.0
MEMORY_SHARE = 0.05  # of the inputs fed back to back to one long-lived decoder under tracemalloc
MIN_MEMORY_INPUTS = 200
MAX_MEMORY_GROWTH_BYTES = 256 * 1024  # a decoder that keeps more than this after thousands of inputs is leaking
EXAMPLES_KEPT = 5

Rng = np.random.Generator


@dataclass
class Case:
    """One fuzz input: its kind, the data, and what a correct decoder must give back (target-specific)."""

    kind: str
    data: Any
    expected: Any = None


@dataclass
class Report:
    """What one target did with its inputs."""

    target: str
    description: str
    inputs: int = 0
    kinds: Counter[str] = field(default_factory=Counter)
    crashes: int = 0
    hangs: int = 0
    wrong_decodes: int = 0
    valid_embedded: int = 0  # valid packets/messages placed among garbage and damage
    valid_recovered: int = 0
    driver_inputs: int = 0  # inputs also run through the driver's decode path
    cpu_s: float = 0.0
    cpu_ms: list[float] = field(default_factory=list, repr=False)
    memory: dict[str, int] = field(default_factory=dict)
    examples: list[dict[str, Any]] = field(default_factory=list)

    def note(self, finding: str, index: int, case: Case, detail: str) -> None:
        if len(self.examples) < EXAMPLES_KEPT:
            self.examples.append({"finding": finding, "input": index, "kind": case.kind, "detail": detail[:300]})

    def as_dict(self) -> dict[str, Any]:
        cpu = np.array(self.cpu_ms) if self.cpu_ms else np.zeros(1)
        return {
            "target": self.target,
            "description": self.description,
            "inputs": self.inputs,
            "kinds": dict(sorted(self.kinds.items())),
            "crashes": self.crashes,
            "hangs": self.hangs,
            "wrong_decodes": self.wrong_decodes,
            "valid_embedded": self.valid_embedded,
            "valid_recovered": self.valid_recovered,
            "driver_inputs": self.driver_inputs,
            "cpu_s": round(self.cpu_s, 2),
            "cpu_ms_median": round(float(np.median(cpu)), 4),
            "cpu_ms_p99": round(float(np.percentile(cpu, 99)), 3),
            "cpu_ms_max": round(float(cpu.max()), 3),
            "memory": self.memory,
            "examples": self.examples,
        }


class Target:
    """A codec under fuzz: ``draw`` builds one input, ``check`` runs it and returns (wrong decodes, valid placed,
    valid recovered), raising whatever the code under test raises; ``stream`` builds a long-lived consumer for the
    memory phase."""

    name = ""
    description = ""
    allowed: tuple[type[BaseException], ...] = (ProtocolError,)

    def draw(self, rng: Rng) -> Case:
        raise NotImplementedError

    def check(self, case: Case, rng: Rng) -> tuple[int, int, int]:
        raise NotImplementedError

    def stream(self) -> Callable[[Case], None]:
        raise NotImplementedError


# ---- shared generators ------------------------------------------------------------------------------------------


def random_bytes(rng: Rng, n: int) -> bytes:
    return rng.integers(0, 256, n, dtype=np.uint8).tobytes()


def random_chunks(rng: Rng, data: bytes) -> list[bytes]:
    """``data`` cut at random sizes: 1 byte, 7 bytes, USB packets, random, or whole."""
    mode = int(rng.integers(0, 5))
    if mode == 0 or len(data) < 2:
        return [data]
    if mode == 1:
        size = [1, 7, 64][int(rng.integers(0, 3))]
        return [data[i : i + size] for i in range(0, len(data), size)]
    cuts = np.sort(
        rng.choice(np.arange(1, len(data)), size=min(len(data) - 1, int(rng.integers(1, 40))), replace=False)
    )
    bounds = [0, *cuts.tolist(), len(data)]
    return [data[a:b] for a, b in itertools.pairwise(bounds)]


def flip_bits(rng: Rng, data: bytes, n: int) -> bytes:
    out = bytearray(data)
    for _ in range(n):
        if out:
            out[int(rng.integers(0, len(out)))] ^= 1 << int(rng.integers(0, 8))
    return bytes(out)


def mutate_bytes(rng: Rng, data: bytes) -> bytes:
    """A few random edits: bit flips, byte overwrites, cuts, duplications, insertions."""
    out = bytearray(data)
    for _ in range(int(rng.integers(1, 6))):
        op = int(rng.integers(0, 5))
        at = int(rng.integers(0, len(out) + 1))
        if op == 0 and out:
            out[min(at, len(out) - 1)] ^= 1 << int(rng.integers(0, 8))
        elif op == 1 and out:
            out[min(at, len(out) - 1)] = int(rng.integers(0, 256))
        elif op == 2:
            del out[at : at + int(rng.integers(1, 16))]
        elif op == 3:
            out[at:at] = out[at : at + int(rng.integers(1, 16))]
        else:
            out[at:at] = random_bytes(rng, int(rng.integers(1, 16)))
    return bytes(out)


def run_chunks(feed: Callable[[bytes], list[Any]], chunks: list[bytes]) -> list[Any]:
    out: list[Any] = []
    for chunk in chunks:
        out += feed(chunk)
    return out


def in_order(expected: list[Any], got: list[Any], same: Callable[[Any, Any], bool]) -> int:
    """How many of ``expected`` appear in ``got`` in order (extra items in ``got`` allowed)."""
    found = 0
    it = iter(got)
    for want in expected:
        for item in it:
            if same(want, item):
                found += 1
                break
        else:
            break
    return found
