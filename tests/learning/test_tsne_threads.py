"""The report's t-SNE runs on one BLAS/OpenMP thread: on a report's ~1,200 points more threads only contend."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from unitac_rig.learning.report import tsne_embeddings


def test_the_tsne_runs_on_one_thread_and_leaves_the_limits_as_they_were(monkeypatch: pytest.MonkeyPatch) -> None:
    from sklearn.manifold import TSNE

    seen: list[list[int]] = []
    original = TSNE.fit_transform

    def recording(self: TSNE, x: np.ndarray, y: object = None) -> np.ndarray:
        seen.append([pool["num_threads"] for pool in threadpool_info()])
        return np.asarray(original(self, x))

    monkeypatch.setattr(TSNE, "fit_transform", recording)
    before = [pool["num_threads"] for pool in threadpool_info()]
    rng = np.random.default_rng(0)
    latents = {s: rng.normal(size=(40, 8)) for s in ("uskin", "papillarray")}
    out = tsne_embeddings(latents, latents, ["uskin", "papillarray"], seed=0)
    assert out["first"].shape == out["last"].shape == (80, 2)
    assert len(seen) == 2 and all(threads and set(threads) == {1} for threads in seen)
    assert [pool["num_threads"] for pool in threadpool_info()] == before
