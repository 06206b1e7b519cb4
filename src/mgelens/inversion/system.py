"""Assembly of the linear system: data vector and curvature matrix (SPEC §6.1).

The blurred operator is M = [L | G]: dense columns L for linear light profiles (MGE
lens light, parametric source), then the blurred mapping matrix G = B f of a pixelized
source, with f the (very sparse) mapping matrix and B the mask-to-mask PSF operator.
With inverse variances w_i = 1/σ_i²:

* data vector D = Mᵀ W r (r = data minus fixed light); Gᵀ W r = fᵀ Bᵀ (W r) needs no G;
* curvature F = Mᵀ W M.

G itself is dense-ish (each image pixel receives light from the ~200 source pixels
under its PSF footprint), so F_GG = Gᵀ W G is the hot spot of a likelihood evaluation.
It is computed tile by tile: for a T×T block of image pixels, the rows of G are built
densely over the union U of source pixels that reach the block (a small scatter through
the PSF), and Gᵀ W G and Lᵀ W G of the block are dense BLAS products scattered into F.
Neighbouring pixels share almost all of their source pixels, so the dense blocks waste
little work and run at BLAS speed.
"""

from dataclasses import dataclass

import numba
import numpy as np
from llvmlite import binding
from numba import prange, types
from numba.extending import get_cython_function_address
from scipy import sparse
from scipy.linalg import blas

from mgelens._jit import njit
from mgelens.convolve import separable_terms
from mgelens.threads import single_threaded_blas

TILE_SIZE = 8

# scipy's BLAS dsyrk under a symbol name that compiled kernels link by name, so that
# they stay cacheable (a ctypes function pointer would be a dynamic global).
binding.add_symbol(
    "mgelens_dsyrk", get_cython_function_address("scipy.linalg.cython_blas", "dsyrk")
)
_DSYRK = types.ExternalFunction("mgelens_dsyrk", types.void(*([types.voidptr] * 10)))

STENCIL_COST_RATIO = 5.0
"""A tile's rows of G cost about k_y k_x scattered additions per output pixel and mapping
non-zero by direct summation, or (T + k_y − 1)(T + k_x − 1) vectorised ones by the stencil
route (:func:`_stencil_rows`), about 5 times cheaper each (measured on a 15×15 HST PSF:
0.37 against 0.15 ms a tile). The stencil route is taken when it is cheaper by that count."""


@dataclass(frozen=True, eq=False)
class TilePlan:
    """Image pixels of a mask grouped into square tiles, for :func:`curvature_matrix`.

    Attributes
    ----------
    psf : ndarray (k_y, k_x)
        The PSF kernel.
    slim_index : ndarray (n_y, n_x) of int
        Slim index of every unmasked pixel, −1 where masked.
    tile_indptr : ndarray (n_tiles + 1,)
        Tile t holds the pixels ``tile_pixels[tile_indptr[t]:tile_indptr[t + 1]]``.
    tile_pixels : ndarray of int
        Slim indices of the pixels, grouped by tile.
    rows, cols : ndarray of int
        Native row and column of ``tile_pixels``.
    psf_u, psf_v : ndarray (r, k_y), (r, k_x)
        Singular-value terms of the PSF (:func:`mgelens.convolve.separable_terms`) when
        r (k_x + k_y) is less than k_x k_y, so that rows of G are built with a row pass
        and a column pass (a Gaussian PSF: r = 1); empty (r = 0) otherwise.
    stencil : bool
        Without separable terms, whether rows of G are built by :func:`_stencil_rows`
        (large full-rank kernels, e.g. HST's 15×15) rather than by direct summation
        (:data:`STENCIL_COST_RATIO`).
    """

    psf: np.ndarray
    slim_index: np.ndarray
    tile_indptr: np.ndarray
    tile_pixels: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    psf_u: np.ndarray
    psf_v: np.ndarray
    stencil: bool

    @classmethod
    def from_mask(cls, mask: np.ndarray, psf: np.ndarray, tile_size: int = TILE_SIZE):
        """Tile the unmasked pixels of ``mask`` (True = excluded) in blocks of ``tile_size``²."""
        slim_index = np.full(mask.shape, -1, dtype=np.int64)
        slim_index[~mask] = np.arange(np.count_nonzero(~mask))
        rows, cols = np.nonzero(~mask)
        tile_id = (rows // tile_size) * (mask.shape[1] // tile_size + 1) + cols // tile_size
        order = np.argsort(tile_id, kind="stable")
        _, counts = np.unique(tile_id[order], return_counts=True)
        indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        u, v = separable_terms(psf)
        if u.shape[0] * sum(psf.shape) >= psf.size:
            u, v = np.zeros((0, psf.shape[0])), np.zeros((0, psf.shape[1]))
        window = (tile_size + psf.shape[0] - 1) * (tile_size + psf.shape[1] - 1)
        return cls(
            psf=np.ascontiguousarray(psf, dtype=float),
            slim_index=slim_index,
            tile_indptr=indptr,
            tile_pixels=slim_index[rows[order], cols[order]],
            rows=rows[order].astype(np.int64),
            cols=cols[order].astype(np.int64),
            psf_u=u,
            psf_v=v,
            stencil=bool(u.shape[0] == 0 and window < STENCIL_COST_RATIO * psf.size),
        )


@dataclass(frozen=True, eq=False)
class DenseTerms:
    """The curvature terms of dense columns L that no mapping matrix changes.

    Attributes
    ----------
    gram : ndarray (n_dense, n_dense)
        F_LL = Lᵀ W L.
    products : ndarray (N_I, n_dense)
        Bᵀ W L, so that F_LS = Lᵀ W B f = (fᵀ Bᵀ W L)ᵀ is one sparse product for any
        mapping matrix f.
    """

    gram: np.ndarray
    products: np.ndarray

    @classmethod
    def build(cls, dense: np.ndarray, inverse_variance: np.ndarray, convolver) -> "DenseTerms":
        """The terms of ``dense`` (N_I, n_dense); ``convolver`` (a
        :class:`mgelens.convolve.Convolver`) gives Bᵀ as a transposed blur."""
        weighted = inverse_variance[:, None] * dense
        return cls(
            weighted_gram(dense, inverse_variance), convolver.transpose_blur_columns(weighted)
        )

    def lens_source(self, mapping: sparse.spmatrix) -> np.ndarray:
        """F_LS = Lᵀ W B f = (fᵀ Bᵀ W L)ᵀ (n_dense, n_source) for the mapping matrix f."""
        return np.asarray(mapping.T @ self.products).T


@dataclass(frozen=True, eq=False)
class WeightedBlurredMapping:
    """W G = W B f of one fixed mapping matrix f, for F_LS = Lᵀ W G of ever-new dense
    columns L in one sparse pass (the LIGHT phase: mass and source fixed, lens light new
    on every call).

    :class:`DenseTerms` gets F_LS from a transposed blur of every column of W L, then a
    sparse product with f; here each column costs nnz(B f) multiply-adds instead, and no
    blur. :meth:`cheaper` chooses between the two by an operation count.

    Attributes
    ----------
    indptr, indices, values : ndarray
        W B f (N_I × n_source) in compressed-column form (one column per source pixel,
        its image rows ascending), int64 index arrays as the compiled pass takes them.
    n_source : int
    """

    indptr: np.ndarray
    indices: np.ndarray
    values: np.ndarray
    n_source: int

    @classmethod
    def build(
        cls, blurred_mapping: sparse.spmatrix, inverse_variance: np.ndarray
    ) -> "WeightedBlurredMapping":
        """From B f (N_I, n_source) and the w_i (N_I,)."""
        matrix = sparse.csc_matrix(sparse.diags(inverse_variance) @ blurred_mapping)
        matrix.sort_indices()
        return cls(
            matrix.indptr.astype(np.int64),
            matrix.indices.astype(np.int64),
            matrix.data,
            matrix.shape[1],
        )

    @staticmethod
    def cheaper(blurred_mapping: sparse.spmatrix, mapping: sparse.spmatrix, convolver) -> bool:
        """Whether nnz(B f) multiply-adds per dense column cost less than the transposed
        blur (``convolver``'s estimate, :meth:`mgelens.convolve.Convolver.column_cost`)
        plus the sparse product with f that :class:`DenseTerms` needs."""
        return blurred_mapping.nnz < convolver.column_cost(include_blurring=False) + mapping.nnz

    def lens_source(self, dense: np.ndarray) -> np.ndarray:
        """F_LS = Lᵀ W B f (n_dense, n_source) of dense columns L (N_I, n_dense)."""
        return _column_sparse_product(
            self.indptr, self.indices, self.values, np.ascontiguousarray(dense), ROW_BLOCK
        ).T


ROW_BLOCK = 256
"""Image rows of L per pass of :func:`_column_sparse_product`: 256 rows of 190 lens-light
columns (390 kB) stay in a core's L2 cache while every source pixel's non-zeros in them
are summed, where a pass over the rows of W B f would scatter each row of L into all of
F_LS (docs/benchmarks.md, "Two exact kernels for 1,000-pixel calls")."""


@njit(parallel=True, fastmath=True)
def _column_sparse_product(indptr, indices, values, dense, row_block):
    """Aᵀ dense (n_cols, n_dense) for A (n_rows × n_cols) in compressed-column form with
    ascending row indices: block by block of ``row_block`` rows of ``dense``, each column
    j of A adds its non-zeros in the block, scaled, to row j of the result. Threads take
    columns, so each writes its own rows."""
    n_cols = indptr.size - 1
    n_rows, n_dense = dense.shape
    out = np.zeros((n_cols, n_dense))
    cursor = indptr[:-1].copy()
    for first in range(0, n_rows, row_block):
        last = first + row_block
        for j in prange(n_cols):
            acc = out[j]
            k = cursor[j]
            end = indptr[j + 1]
            while k < end and indices[k] < last:
                value = values[k]
                source = dense[indices[k]]
                for m in range(n_dense):
                    acc[m] += value * source[m]
                k += 1
            cursor[j] = k
    return out


def weighted_gram(dense: np.ndarray, inverse_variance: np.ndarray) -> np.ndarray:
    """Lᵀ W L of dense columns L (N_I, n) as a symmetric rank-N update (BLAS syrk), half
    the work of a general product."""
    if dense.shape[1] == 0:  # LAPACK rejects a leading dimension of 0
        return np.zeros((0, 0))
    scaled = np.sqrt(inverse_variance)[:, None] * dense
    upper = blas.dsyrk(1.0, scaled.T, trans=0, lower=0)  # scaled.T is Fortran-ordered
    return upper + np.triu(upper, 1).T


def data_vector(
    dense: np.ndarray,
    mapping: sparse.csr_matrix | None,
    psf_operator: sparse.csr_matrix | None,
    inverse_variance: np.ndarray,
    residual_data: np.ndarray,
    blurred_weighted: np.ndarray | None = None,
) -> np.ndarray:
    """D = [L | B f]ᵀ W r; ``mapping`` f and ``psf_operator`` B may be None (no source).

    ``blurred_weighted``, if given, is Bᵀ W r already computed (it does not change while
    the data and any fixed light do: :attr:`mgelens.fit.FitDataset.blurred_weighted_data`).
    """
    weighted = inverse_variance * residual_data
    parts = [dense.T @ weighted]
    if mapping is not None:
        if blurred_weighted is None:
            blurred_weighted = psf_operator.T @ weighted
        parts.append(mapping.T @ blurred_weighted)
    return np.concatenate(parts)


def curvature_matrix(
    dense: np.ndarray,
    mapping: sparse.csr_matrix | None,
    plan: TilePlan | None,
    inverse_variance: np.ndarray,
    dense_terms: DenseTerms | None = None,
) -> np.ndarray:
    """F = Mᵀ W M for M = [L | B f] as a dense symmetric matrix (f, plan None: no source).

    ``dense_terms``, if given, are L's :class:`DenseTerms` (phases that keep the lens
    light fixed cache them): then F_LS is one sparse product and the tiles compute F_SS
    only (130 lens-light columns and 500 source pixels: 1 ms instead of 12 ms, and F_LL
    is not recomputed).
    """
    n_dense = dense.shape[1]
    n_source = 0 if mapping is None else mapping.shape[1]
    f = np.empty((n_dense + n_source, n_dense + n_source))
    if dense_terms is None:
        f[:n_dense, :n_dense] = weighted_gram(dense, inverse_variance)
    else:
        f[:n_dense, :n_dense] = dense_terms.gram
    if mapping is not None:
        mapping = mapping.tocsr()
        tiled = dense if dense_terms is None else dense[:, :0]
        with single_threaded_blas():
            f_ss, f_ls = _tile_curvature(
                plan.tile_indptr,
                plan.tile_pixels,
                plan.rows,
                plan.cols,
                plan.slim_index,
                plan.psf,
                plan.psf_u,
                plan.psf_v,
                mapping.indptr.astype(np.int64),
                mapping.indices.astype(np.int64),
                mapping.data,
                n_source,
                np.ascontiguousarray(tiled),
                inverse_variance,
                numba.get_num_threads(),
                plan.stencil,
            )
        if dense_terms is not None:
            f_ls = dense_terms.lens_source(mapping)
        f[n_dense:, n_dense:] = f_ss
        f[:n_dense, n_dense:] = f_ls
        f[n_dense:, :n_dense] = f_ls.T
    return f


@njit(inline="always")
def _add_mapping_row(out, k, weight, f_indptr, f_indices, f_values, position):
    """out[position[j]] += weight · f[k, j] over the non-zeros of mapping row k."""
    for p in range(f_indptr[k], f_indptr[k + 1]):
        out[position[f_indices[p]]] += weight * f_values[p]


@njit
def _direct_rows(g, rows, cols, slim_index, psf, f_indptr, f_indices, f_values, position):
    """Rows of G = B f for the pixels (rows, cols) of one tile, into ``g``, summing the
    full kernel: g[i] += psf[a, b] f[(r_i − a + h_y, c_i − b + h_x)]."""
    n_y, n_x = slim_index.shape
    k_y, k_x = psf.shape
    h_y, h_x = k_y // 2, k_x // 2
    for i in range(rows.size):
        for ka in range(k_y):
            r = rows[i] - ka + h_y
            if r < 0 or r >= n_y:
                continue
            for kb in range(k_x):
                cc = cols[i] - kb + h_x
                if cc < 0 or cc >= n_x or slim_index[r, cc] < 0:
                    continue
                _add_mapping_row(
                    g[i], slim_index[r, cc], psf[ka, kb], f_indptr, f_indices, f_values, position
                )


@njit
def _separable_rows(
    g, rows, cols, slim_index, psf_u, psf_v, f_indptr, f_indices, f_values, position, n_union
):
    """Rows of G = B f for the pixels (rows, cols) of one tile, into ``g`` (n_out, n_union),
    with B = Σ_k u_k v_kᵀ: per term a row pass h[r, c] = Σ_b v_k[b] f[(r, c − b + h_x)]
    over the tile's columns and its rows ± h_y (a sparse scatter), then a dense column pass
    g[i] += Σ_a u_k[a] h[r_i − a + h_y, c_i]. ``position`` maps source pixels to g's
    columns."""
    n_y, n_x = slim_index.shape
    k_y, k_x = psf_u.shape[1], psf_v.shape[1]
    h_y, h_x = k_y // 2, k_x // 2
    r_lo, r_hi = rows.min() - h_y, rows.max() + h_y
    c_lo, c_hi = cols.min(), cols.max()
    n_r, n_c = r_hi - r_lo + 1, c_hi - c_lo + 1
    h = np.empty((n_r, n_c, n_union))
    for term in range(psf_u.shape[0]):
        h[:] = 0.0
        for r in range(max(r_lo, 0), min(r_hi + 1, n_y)):
            for c in range(n_c):
                for kb in range(k_x):
                    cc = c + c_lo - kb + h_x
                    if cc < 0 or cc >= n_x or slim_index[r, cc] < 0:
                        continue
                    _add_mapping_row(
                        h[r - r_lo, c],
                        slim_index[r, cc],
                        psf_v[term, kb],
                        f_indptr,
                        f_indices,
                        f_values,
                        position,
                    )
        for i in range(rows.size):
            c = cols[i] - c_lo
            for ka in range(k_y):
                weight = psf_u[term, ka]
                row = h[rows[i] - ka + h_y - r_lo, c]
                for x in range(n_union):
                    g[i, x] += weight * row[x]


@njit(fastmath=True)
def _stencil_rows(rows, cols, slim_index, psf, f_indptr, f_indices, f_values, position, n_union):
    """Rows of G = B f for the pixels (rows, cols) of one tile, returned as (n_out, n_union).

    For a full-rank kernel: every input pixel w within the kernel's reach of the tile gets
    its column of kernel weights towards the tile's outputs, b_w (n_out); each non-zero
    f[w, a] then adds f[w, a] · b_w to the row of source pixel a of Gᵀ, a contiguous
    update over the outputs (vectorised) instead of a scattered one per kernel tap.
    """
    n_y, n_x = slim_index.shape
    k_y, k_x = psf.shape
    h_y, h_x = k_y // 2, k_x // 2
    r_lo, r_hi = max(rows.min() - h_y, 0), min(rows.max() + h_y, n_y - 1)
    c_lo, c_hi = max(cols.min() - h_x, 0), min(cols.max() + h_x, n_x - 1)
    local = np.full((r_hi - r_lo + 1, c_hi - c_lo + 1), -1, dtype=np.int64)
    n_in = 0
    for r in range(r_lo, r_hi + 1):
        for cc in range(c_lo, c_hi + 1):
            k = slim_index[r, cc]
            if k >= 0 and f_indptr[k + 1] > f_indptr[k]:
                local[r - r_lo, cc - c_lo] = n_in
                n_in += 1
    n_out = rows.size
    weights = np.zeros((n_in, n_out))  # weights[w, i]: kernel weight from input w to output i
    for i in range(n_out):
        for ka in range(k_y):
            r = rows[i] - ka + h_y - r_lo
            if r < 0 or r >= local.shape[0]:
                continue
            for kb in range(k_x):
                c = cols[i] - kb + h_x - c_lo
                if 0 <= c < local.shape[1] and local[r, c] >= 0:
                    weights[local[r, c], i] = psf[ka, kb]
    g_t = np.zeros((n_union, n_out))
    for r in range(local.shape[0]):
        for c in range(local.shape[1]):
            w = local[r, c]
            if w < 0:
                continue
            k = slim_index[r + r_lo, c + c_lo]
            for p in range(f_indptr[k], f_indptr[k + 1]):
                row = g_t[position[f_indices[p]]]
                value = f_values[p]
                for i in range(n_out):
                    row[i] += value * weights[w, i]
    return g_t.T.copy()


@njit
def _gram_upper(a):
    """The upper triangle of aᵀa (n × n, C order; the strict lower triangle zero) for a
    C-ordered (k, n) array ``a``: BLAS dsyrk, half the multiply-adds of a general product
    (a in C order is aᵀ to Fortran, so its 'lower' triangle of aᵀa is this upper one)."""
    k, n = a.shape
    out = np.zeros((n, n))
    flags = np.array([ord("L"), ord("N")], dtype=np.uint8)
    sizes = np.array([n, k, n, n], dtype=np.int32)  # n, k, lda, ldc
    scalars = np.array([1.0, 0.0])  # alpha, beta
    _DSYRK(
        flags[0:].ctypes.data,
        flags[1:].ctypes.data,
        sizes[0:].ctypes.data,
        sizes[1:].ctypes.data,
        scalars[0:].ctypes.data,
        a.ctypes.data,
        sizes[2:].ctypes.data,
        scalars[1:].ctypes.data,
        out.ctypes.data,
        sizes[3:].ctypes.data,
    )
    return out


# Kept whole: one prange loop over chunks, whose steps share each chunk's scratch and partial sums.
@njit(parallel=True)
def _tile_curvature(
    tile_indptr,
    tile_pixels,
    rows,
    cols,
    slim_index,
    psf,
    psf_u,
    psf_v,
    f_indptr,
    f_indices,
    f_values,
    n_source,
    light,
    inverse_variance,
    n_chunks,
    stencil,
):
    n_tiles = tile_indptr.size - 1
    n_light = light.shape[1]
    n_y, n_x = slim_index.shape
    k_y, k_x = psf.shape
    h_y, h_x = k_y // 2, k_x // 2
    parts_ss = np.zeros((n_chunks, n_source, n_source))
    parts_ls = np.zeros((n_chunks, n_light, n_source))
    for c in prange(n_chunks):
        stamp = np.full(n_source, -1, dtype=np.int64)
        position = np.zeros(n_source, dtype=np.int64)
        union = np.zeros(n_source, dtype=np.int64)
        for t in range(c * n_tiles // n_chunks, (c + 1) * n_tiles // n_chunks):
            start, end = tile_indptr[t], tile_indptr[t + 1]
            r_lo, r_hi = rows[start:end].min() - h_y, rows[start:end].max() + h_y
            c_lo, c_hi = cols[start:end].min() - h_x, cols[start:end].max() + h_x
            n_union = 0
            for r in range(max(r_lo, 0), min(r_hi + 1, n_y)):
                for cc in range(max(c_lo, 0), min(c_hi + 1, n_x)):
                    k = slim_index[r, cc]
                    if k < 0:
                        continue
                    for p in range(f_indptr[k], f_indptr[k + 1]):
                        a = f_indices[p]
                        if stamp[a] != t:
                            stamp[a] = t
                            position[a] = n_union
                            union[n_union] = a
                            n_union += 1
            if n_union == 0:
                continue
            # ascending source order: the upper-triangle scatter below is one increasing
            # run of columns per row of F (cache friendly)
            union[:n_union].sort()
            for x in range(n_union):
                position[union[x]] = x
            n_out = end - start
            g = np.zeros((n_out, n_union))
            if psf_u.shape[0] > 0:
                _separable_rows(
                    g,
                    rows[start:end],
                    cols[start:end],
                    slim_index,
                    psf_u,
                    psf_v,
                    f_indptr,
                    f_indices,
                    f_values,
                    position,
                    n_union,
                )
            elif stencil:
                g = _stencil_rows(
                    rows[start:end],
                    cols[start:end],
                    slim_index,
                    psf,
                    f_indptr,
                    f_indices,
                    f_values,
                    position,
                    n_union,
                )
            else:
                _direct_rows(
                    g,
                    rows[start:end],
                    cols[start:end],
                    slim_index,
                    psf,
                    f_indptr,
                    f_indices,
                    f_values,
                    position,
                )
            # √w_i g_i, so that the block Gᵀ W G is one symmetric rank-k update
            for i in range(n_out):
                scale = np.sqrt(inverse_variance[tile_pixels[start + i]])
                for j in range(n_union):
                    g[i, j] *= scale
            block = _gram_upper(g)
            for x in range(n_union):
                row = parts_ss[c, union[x]]
                for y in range(x, n_union):
                    row[union[y]] += block[x, y]
            if n_light > 0:
                light_t = np.empty((n_light, n_out))
                for i in range(n_out):
                    scale = np.sqrt(inverse_variance[tile_pixels[start + i]])
                    light_t[:, i] = scale * light[tile_pixels[start + i]]
                block_ls = np.dot(light_t, g)
                for k in range(n_light):
                    for y in range(n_union):
                        parts_ls[c, k, union[y]] += block_ls[k, y]
    upper = parts_ss.sum(axis=0)
    for a in range(n_source):  # mirror the upper triangle
        for b in range(a):
            upper[a, b] = upper[b, a]
    return upper, parts_ls.sum(axis=0)
