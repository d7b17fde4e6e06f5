"""Which photos look alike: a bag of visual words trained on the capture's own SIFT descriptors, the same on
every run (loop detection, retrieval matching and the pairs between takes, :mod:`curate.sfm.matching`).

COLMAP's vocabulary tree (``pycolmap.VisualIndex``, faiss k-means inside) is not seeded: three builds on the
same descriptors, with one thread or two, gave three trees, so the pairs loop detection matched, and the model
after them, changed from run to run (office.mp4 at half its frame rate: about 300 of 1,672 pairs differed
between two runs of the same matching; docs/sfm-investigations.md, "The same input, the same model").
Here the words are a two-level k-means (seeded: ``branching[0]`` words, each split into ``branching[1]``) on an
even sample of the capture's descriptors (:func:`curate.sfm.features.tree_sample`);
each photo is a tf-idf histogram of its descriptors' words, and photos are ranked by cosine similarity, ties
by name order. Everything is numpy, with sums whose order no thread decides: the same photos give the same
ranking on every run.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)


@dataclass
class Index:
    """A trained vocabulary and the photos it holds."""

    top: np.ndarray
    """[k1, 128] float32 first-level centroids."""
    leaves: list[np.ndarray]
    """k1 arrays [k2_i, 128]: each first-level word's second-level centroids."""
    offsets: np.ndarray
    """[k1 + 1] first word id of each first-level word's leaves (the last: the vocabulary's size)."""
    names: list[str]
    """The photos, in name order."""
    vectors: np.ndarray
    """[n, words] float32 tf-idf histograms, unit length (zero for a photo without descriptors)."""

    @property
    def n_words(self) -> int:
        return int(self.offsets[-1])


def nearest(x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """[n] index of the centroid of ``c`` ([k, D]) nearest to each row of ``x`` ([n, D]), ties to the lower index.
    In float64 through BLAS, in blocks of rows; BLAS splits the rows and columns of a product among its threads,
    never the sum over D, so the distances do not depend on the threads."""
    x = np.asarray(x, np.float64)
    c = np.asarray(c, np.float64)
    cc = np.einsum("ij,ij->i", c, c)
    out = np.empty(len(x), np.int64)
    for i in range(0, len(x), 32768):
        xb = x[i:i + 32768]
        out[i:i + 32768] = np.argmin(cc[None, :] - 2.0 * (xb @ c.T), axis=1)
    return out


def _kmeans(x: np.ndarray, k: int, rng: np.random.Generator, iters: int = 10) -> np.ndarray:
    """[<= k, D] centroids of ``x`` by seeded k-means (k of its points to start, ``iters`` Lloyd steps); clusters
    left empty are dropped."""
    x = np.asarray(x, np.float64)
    k = int(min(k, len(x)))
    if k <= 1:
        return x.mean(0, keepdims=True).astype(np.float32)
    c = x[np.sort(rng.choice(len(x), k, replace=False))]
    for _ in range(iters):
        lab = nearest(x, c)
        order = np.argsort(lab, kind="stable")
        used, starts, counts = np.unique(lab[order], return_index=True, return_counts=True)
        c = np.add.reduceat(x[order], starts, axis=0) / counts[:, None]   # the clusters left empty are gone
    return c.astype(np.float32)


def train(sample: np.ndarray, seed: int, branching: tuple[int, int] = (64, 32)) -> tuple[np.ndarray, list, np.ndarray]:
    """(first-level centroids, second-level centroids per first-level word, word-id offsets) of ``sample``
    ([N, 128] descriptors), the same for the same sample and seed."""
    rng = np.random.default_rng(seed)
    x = np.asarray(sample, np.float32)
    if len(x) == 0:
        x = np.zeros((1, 128), np.float32)
    top = _kmeans(x, branching[0], rng)
    lab = nearest(x, top)
    leaves = [_kmeans(x[lab == j], branching[1], rng) if np.any(lab == j) else top[j:j + 1] for j in range(len(top))]
    offsets = np.concatenate([[0], np.cumsum([len(v) for v in leaves])]).astype(np.int64)
    return top, leaves, offsets


def words(desc: np.ndarray, top: np.ndarray, leaves: list, offsets: np.ndarray) -> np.ndarray:
    """[n] word id of each descriptor of ``desc`` ([n, 128]): the nearest first-level centroid, then the nearest of
    its leaves."""
    d = np.asarray(desc, np.float64)
    if len(d) == 0:
        return np.zeros(0, np.int64)
    lab = nearest(d, top)
    out = np.empty(len(d), np.int64)
    for j in np.unique(lab):
        m = lab == j
        out[m] = offsets[j] + nearest(d[m], leaves[j])
    return out


def tfidf(histograms: np.ndarray) -> np.ndarray:
    """[n, W] unit-length tf-idf vectors of word counts ``histograms`` ([n, W]); a photo without words stays zero."""
    h = np.asarray(histograms, np.float64)
    df = np.count_nonzero(h, axis=0)
    idf = np.log((len(h) + 1.0) / (df + 1.0))
    v = h / np.maximum(h.sum(1, keepdims=True), 1.0) * idf
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return (v / np.where(n > 0, n, 1.0)).astype(np.float32)


def build(db: Path, seed: int, max_descriptors: int = 100_000, branching: tuple[int, int] = (64, 32)) -> Index:
    """The :class:`Index` of every photo of COLMAP's database ``db``, trained on an even sample of at most
    ``max_descriptors`` of their SIFT descriptors."""
    from curate.sfm.features import read_descriptors, tree_sample
    t = time.perf_counter()
    names, desc = read_descriptors(db)
    rng = np.random.default_rng(seed)
    sample = tree_sample(iter(desc), len(desc), max_descriptors, rng)
    top, leaves, offsets = train(sample, seed, branching)
    W = int(offsets[-1])
    hist = np.zeros((len(names), W), np.float32)
    for i, d in enumerate(desc):
        if len(d):
            hist[i] = np.bincount(words(d, top, leaves, offsets), minlength=W)
    index = Index(top, leaves, offsets, names, tfidf(hist))
    logger.info("sfm: visual words: %d from %d descriptors, %d photos indexed in %.1f s", W, len(sample), len(names),
                time.perf_counter() - t)
    return index


def ranked(index: Index, queries: list[str], candidates: list[str] | None = None, k: int | None = None):
    """For each query (a name of ``index``): (query, [candidate names, most similar first]) among ``candidates``
    (default: every photo but the query), the first ``k`` of them (default: all). Ties go to name order."""
    pos = {n: i for i, n in enumerate(index.names)}
    cand = np.array([pos[n] for n in (candidates if candidates is not None else index.names)], np.int64)
    cand.sort()
    V = index.vectors.astype(np.float64)
    for q in queries:
        i = pos[q]
        c = cand[cand != i]
        s = np.einsum("ij,j->i", V[c], V[i], optimize=False)   # no BLAS: the same sums whatever the threads
        order = np.lexsort((c, -s))     # highest similarity first, then name order
        order = order[:k] if k is not None else order
        yield q, [index.names[j] for j in c[order]]


def save(index: Index, path: Path) -> None:
    """Write ``index`` to ``path`` (numpy's .npz)."""
    np.savez(path, top=index.top, offsets=index.offsets, names=np.array(index.names, dtype=str),
             vectors=index.vectors, **{f"leaf{j}": v for j, v in enumerate(index.leaves)})


def load(path: Path) -> Index:
    """The :class:`Index` :func:`save` wrote."""
    with np.load(path) as z:
        top = z["top"]
        return Index(top, [z[f"leaf{j}"] for j in range(len(top))], z["offsets"], [str(n) for n in z["names"]],
                     z["vectors"])
