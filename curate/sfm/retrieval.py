"""Which photos look alike: a bag of visual words trained on the capture's own SIFT descriptors, the same on
every run (loop detection, retrieval matching and the pairs between takes, :mod:`curate.sfm.matching`).

COLMAP's vocabulary tree (``pycolmap.VisualIndex``, faiss k-means inside) is not seeded: three builds on the
same descriptors, with one thread or two, gave three trees, so the pairs loop detection matched, and the model
after them, changed from run to run (office.mp4 at half its frame rate: about 300 of 1,672 pairs differed
between two runs of the same matching; docs/sfm.md#same-model).
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
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import scipy.sparse

logger = logging.getLogger(__name__)

BRANCHING = (256, 64)
"""The words: 256 first-level words, each split into 64 (16,384 in all). office.mp4's loop detection with guided
matching: 2,048 words (64 x 32) found 309 verified loop pairs and kept 359 of 371 frames in a model bent by up to
5 deg (median 2.62 deg from the truth, 14 frames over 5); 16,384 words found 379 and kept all 371 (1.98 deg, 6 over
5); without guided matching both split the walk (docs/investigations/sfm.md#same-input-same-model)."""


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
    vectors: "scipy.sparse.csr_matrix"
    """[n, words] tf-idf histograms, unit length (zero for a photo without descriptors), sparse: a photo holds a
    few thousand of the 16,384 words, so the index grows with the descriptors, not photos x words."""

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


def train(sample: np.ndarray, seed: int, branching: tuple[int, int] = BRANCHING) -> tuple[np.ndarray, list, np.ndarray]:
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


def tfidf(histograms) -> "scipy.sparse.csr_matrix":
    """[n, W] unit-length tf-idf vectors (sparse) of word counts ``histograms`` ([n, W], dense or sparse); a photo
    without words stays zero."""
    from scipy import sparse
    h = sparse.csr_matrix(histograms, dtype=np.float64)
    h.sum_duplicates()
    h.sort_indices()
    n = h.shape[0]
    df = np.bincount(h.indices[h.data != 0], minlength=h.shape[1])
    idf = np.log((n + 1.0) / (df + 1.0))
    rows = np.repeat(np.arange(n), np.diff(h.indptr))
    total = np.bincount(rows, weights=h.data, minlength=n)
    data = h.data / np.maximum(total, 1.0)[rows] * idf[h.indices]
    norm = np.sqrt(np.bincount(rows, weights=data * data, minlength=n))
    data = data / np.where(norm > 0, norm, 1.0)[rows]
    return sparse.csr_matrix((data, h.indices.copy(), h.indptr.copy()), shape=h.shape)


def build(db: Path, seed: int, max_descriptors: int = 100_000, branching: tuple[int, int] = BRANCHING) -> Index:
    """The :class:`Index` of every photo of COLMAP's database ``db``, trained on an even sample of at most
    ``max_descriptors`` of their SIFT descriptors."""
    from curate.sfm.features import read_descriptors, tree_sample
    t = time.perf_counter()
    names, desc = read_descriptors(db)
    rng = np.random.default_rng(seed)
    sample = tree_sample(iter(desc), len(desc), max_descriptors, rng)
    top, leaves, offsets = train(sample, seed, branching)
    from scipy import sparse
    W = int(offsets[-1])
    cols, counts, indptr = [], [], [0]
    for d in desc:
        w, c = np.unique(words(d, top, leaves, offsets), return_counts=True) if len(d) else (np.zeros(0, np.int64),
                                                                                            np.zeros(0, np.int64))
        cols.append(w)
        counts.append(c)
        indptr.append(indptr[-1] + len(w))
    hist = sparse.csr_matrix((np.concatenate(counts or [np.zeros(0)]).astype(np.float64),
                              np.concatenate(cols or [np.zeros(0, np.int64)]), np.array(indptr)),
                             shape=(len(names), W))
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
    V = index.vectors.tocsr()
    queries = list(queries)
    for b0 in range(0, len(queries), 256):   # blocks of queries: one sparse product each
        block = queries[b0:b0 + 256]
        # scipy's sparse product, one thread: each similarity summed over the candidate's words in their order,
        # the same sums on every run and whatever the block
        S = (V @ V[[pos[q] for q in block]].T).toarray()
        for col, q in enumerate(block):
            i = pos[q]
            c = cand[cand != i]
            s = S[c, col]
            order = np.lexsort((c, -s))     # highest similarity first, then name order
            order = order[:k] if k is not None else order
            yield q, [index.names[j] for j in c[order]]


def save(index: Index, path: Path) -> None:
    """Write ``index`` to ``path`` (numpy's .npz)."""
    v = index.vectors.tocsr()
    np.savez(path, top=index.top, offsets=index.offsets, names=np.array(index.names, dtype=str),
             v_data=v.data, v_indices=v.indices, v_indptr=v.indptr, v_shape=np.array(v.shape),
             **{f"leaf{j}": x for j, x in enumerate(index.leaves)})


def load(path: Path) -> Index:
    """The :class:`Index` :func:`save` wrote."""
    with np.load(path) as z:
        from scipy import sparse
        top = z["top"]
        v = sparse.csr_matrix((z["v_data"], z["v_indices"], z["v_indptr"]), shape=tuple(z["v_shape"]))
        return Index(top, [z[f"leaf{j}"] for j in range(len(top))], z["offsets"], [str(n) for n in z["names"]], v)
