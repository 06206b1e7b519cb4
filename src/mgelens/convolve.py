"""PSF convolution of images and of many masked columns at once (SPEC §1.4).

Convention: a true 2D convolution with zero padding, the same as
``scipy.signal.convolve2d(image, psf, mode="same")`` for an odd-sized kernel:
``out[r, c] = Σ_{a,b} psf[a, b] · in[r − a + k_y//2, c − b + k_x//2]``.

Three routes give identical results to round-off: *direct* summation as a sparse
operator (fast for few columns), *FFT* (large kernels, many dense columns) and
*separable* summation over the kernel's singular-value terms, PSF = Σ_k u_k v_kᵀ (a row
pass then a column pass per term; a Gaussian PSF is one term, so a 9×9 kernel costs 18
multiply-adds per pixel instead of 81). Terms whose sum changes no kernel entry by more
than :data:`SEPARABLE_TOLERANCE` of the peak are dropped. ``method="auto"`` picks the
cheapest route by an operation count.
"""

from dataclasses import dataclass, field
from functools import cached_property

import numba
import numpy as np
import scipy.fft
from scipy import signal, sparse

from mgelens._jit import njit
from mgelens.grid import blurring_mask

SEPARABLE_TOLERANCE = 1e-12
"""Largest kernel entry error, relative to the peak, of the separable route's terms."""


def check_psf(psf: np.ndarray) -> np.ndarray:
    """Return ``psf`` as float64 after checking it is 2D, odd-sized and finite."""
    psf = np.asarray(psf, dtype=float)
    if psf.ndim != 2 or psf.shape[0] % 2 == 0 or psf.shape[1] % 2 == 0:
        raise ValueError(f"PSF must be a 2D array of odd size, got shape {psf.shape}")
    if not np.all(np.isfinite(psf)):
        raise ValueError("PSF contains NaN or inf")
    return psf


def trimmed_psf(psf: np.ndarray, relative_floor: float) -> np.ndarray:
    """The smallest centred odd sub-kernel holding every entry ≥ ``relative_floor`` × peak.

    Entries outside it are all below the floor (e.g. the far wings of a Gaussian kernel,
    which are < 1e−10 of the peak beyond 6.8σ): dropping them changes no model image
    at any measurable level but shrinks every convolution. Kept entries are unchanged.
    """
    psf = check_psf(psf)
    if relative_floor <= 0.0:
        return psf
    rows, cols = np.nonzero(np.abs(psf) >= relative_floor * np.abs(psf).max())
    cy, cx = psf.shape[0] // 2, psf.shape[1] // 2
    hy = int(max(cy - rows.min(), rows.max() - cy))
    hx = int(max(cx - cols.min(), cols.max() - cx))
    return psf[cy - hy : cy + hy + 1, cx - hx : cx + hx + 1].copy()


def _direct_cost(psf: np.ndarray, n_pixels: int) -> float:
    return float(psf.size) * n_pixels


def _fft_cost(padded_shape: tuple[int, int]) -> float:
    n = padded_shape[0] * padded_shape[1]
    return 4.0 * n * np.log2(n)


def separable_terms(psf: np.ndarray, tolerance: float = SEPARABLE_TOLERANCE) -> tuple:
    """The fewest singular-value terms (u (r, k_y), v (r, k_x)) with Σ_k u_k v_kᵀ equal to
    ``psf`` within ``tolerance`` × its peak at every entry (rank 1 for a Gaussian)."""
    psf = check_psf(psf)
    left, singular, right = np.linalg.svd(psf, full_matrices=False)
    u = left * singular[None, :]
    floor = tolerance * np.abs(psf).max()
    for rank in range(1, singular.size + 1):
        if np.abs(u[:, :rank] @ right[:rank] - psf).max() <= floor:
            break
    return np.ascontiguousarray(u[:, :rank].T), np.ascontiguousarray(right[:rank])


@njit(fastmath=True)
def _separable_blur(columns, index_map, out_cols, out_row_ptr, pass_lo, pass_hi, u, v):
    """Blur ``columns`` (n_in, n_col) and return them at the output pixels.

    Frame: the bounding box of the input pixels. ``index_map`` (n_r, n_c) holds each box
    pixel's row in ``columns`` (−1: no input, zero light). Output pixels of box row r are
    ``out_row_ptr[r]:out_row_ptr[r + 1]``, at box columns ``out_cols``. Per term k: a row pass
    t[i, c] = Σ_b v_k[b] in[i, c − b + h_x] for c in [pass_lo[i], pass_hi[i]) (the columns
    output rows within h_y of i read), then out[r, c] += Σ_a u_k[a] t[r − a + h_y, c]. The
    row passes live in a ring of k_y rows, so the working set stays small whatever the
    image size; columns are innermost (vectorised).
    """
    n_r, n_c = index_map.shape
    n_col = columns.shape[1]
    n_terms, ky = u.shape
    kx = v.shape[1]
    hy, hx = ky // 2, kx // 2
    out = np.zeros((out_cols.size, n_col))
    ring = np.empty((ky, n_c, n_col))
    for k in range(n_terms):
        for i in range(n_r + hy):
            if i < n_r:
                slot = ring[i % ky]
                for c in range(pass_lo[i], pass_hi[i]):
                    slot[c, :] = 0.0
                    for b in range(kx):
                        cc = c - b + hx
                        j = index_map[i, cc] if 0 <= cc < n_c else -1
                        if j >= 0:
                            w = v[k, b]
                            for m in range(n_col):
                                slot[c, m] += w * columns[j, m]
            r = i - hy
            if r < 0:
                continue
            for p in range(out_row_ptr[r], out_row_ptr[r + 1]):
                c = out_cols[p]
                for a in range(ky):
                    row = r - a + hy
                    if 0 <= row < n_r:
                        w = u[k, a]
                        slot = ring[row % ky]
                        for m in range(n_col):
                            out[p, m] += w * slot[c, m]
    return out


def _separable_geometry(in_mask: np.ndarray, out_mask: np.ndarray, kernel_shape) -> tuple:
    """Index map, output pixels and row-pass column ranges of :func:`_separable_blur`
    for inputs on the unmasked pixels of ``in_mask`` and outputs on those of ``out_mask``
    (which must lie inside the inputs' bounding box)."""
    rows, cols = np.nonzero(~in_mask)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    index_map = np.full((r1 - r0, c1 - c0), -1, dtype=np.int64)
    index_map[rows - r0, cols - c0] = np.arange(rows.size)
    out_rows, out_cols = np.nonzero(~out_mask)
    out_rows, out_cols = out_rows - r0, out_cols - c0
    n_r = r1 - r0
    out_row_ptr = np.searchsorted(out_rows, np.arange(n_r + 1))
    hy = kernel_shape[0] // 2
    pass_lo = np.full(n_r, c1 - c0, dtype=np.int64)
    pass_hi = np.zeros(n_r, dtype=np.int64)
    for r in range(n_r):
        span = out_cols[out_row_ptr[r] : out_row_ptr[r + 1]]
        if span.size:
            near = slice(max(r - hy, 0), min(r + hy + 1, n_r))
            pass_lo[near] = np.minimum(pass_lo[near], span.min())
            pass_hi[near] = np.maximum(pass_hi[near], span.max() + 1)
    return index_map, out_cols, out_row_ptr, pass_lo, pass_hi


def convolve_image(image: np.ndarray, psf: np.ndarray, method: str = "auto") -> np.ndarray:
    """Convolve a native 2D image with an odd PSF (zero padding, output of the same shape)."""
    psf = check_psf(psf)
    image = np.asarray(image, dtype=float)
    if method == "auto":
        padded = tuple(s + k - 1 for s, k in zip(image.shape, psf.shape, strict=True))
        method = "direct" if _direct_cost(psf, image.size) < _fft_cost(padded) else "fft"
    if method == "direct":
        return signal.convolve2d(image, psf, mode="same")
    if method == "fft":
        return signal.fftconvolve(image, psf, mode="same")
    raise ValueError(f"unknown convolution method {method!r}; use 'auto', 'direct' or 'fft'")


def psf_operator(in_mask: np.ndarray, out_mask: np.ndarray, psf: np.ndarray) -> sparse.csr_matrix:
    """Sparse matrix B (n_out × n_in) with ``B @ v_in`` = PSF ⊗ v, cut to ``out_mask``.

    ``v_in`` is a slim vector over the unmasked pixels of ``in_mask`` (zero elsewhere);
    the result is slim over the unmasked pixels of ``out_mask``. Masks: True = excluded.
    """
    psf = check_psf(psf)
    ky, kx = psf.shape
    out_index = np.full(out_mask.shape, -1, dtype=np.int64)
    out_index[~out_mask] = np.arange(np.count_nonzero(~out_mask))
    rows_in, cols_in = np.nonzero(~in_mask)
    da, db = np.meshgrid(np.arange(ky) - ky // 2, np.arange(kx) - kx // 2, indexing="ij")
    r_out = rows_in[:, None] + da.ravel()[None, :]
    c_out = cols_in[:, None] + db.ravel()[None, :]
    inside = (r_out >= 0) & (r_out < in_mask.shape[0]) & (c_out >= 0) & (c_out < in_mask.shape[1])
    j_in = np.broadcast_to(np.arange(rows_in.size)[:, None], r_out.shape)
    values = np.broadcast_to(psf.ravel()[None, :], r_out.shape)
    i_out = np.full(r_out.shape, -1, dtype=np.int64)
    i_out[inside] = out_index[r_out[inside], c_out[inside]]
    keep = (i_out >= 0) & (values != 0.0)
    return sparse.csr_matrix(
        (values[keep], (i_out[keep], j_in[keep])), shape=(out_index.max() + 1, rows_in.size)
    )


def wrap_free_length(n_in: int, first_out: int, last_out: int, half_kernel: int) -> int:
    """Shortest circular-convolution length that gives the linear convolution at the
    outputs ``first_out``…``last_out`` of inputs on 0…``n_in`` − 1 (kernel half-width h).

    An output i reads inputs i − h … i + h. None of them may wrap: the ones below 0 land
    at N + (i − h), which must be ≥ ``n_in`` (the zero padding), and none may lie at or
    beyond N. A fit mask inside its blurring region (outputs h … n − 1 − h) needs N = n,
    not the n + 2h of a full linear convolution.
    """
    return max(n_in, n_in + half_kernel - first_out, last_out + half_kernel + 1)


@njit
def _column_boxes(columns, rows, cols):
    """Per column, the (first row, last row, first col, last col) of its nonzero inputs at
    frame positions (``rows``, ``cols``); (0, −1, 0, −1) for an all-zero column."""
    n_col = columns.shape[1]
    boxes = np.empty((n_col, 4), dtype=np.int64)
    boxes[:, 0] = np.iinfo(np.int64).max
    boxes[:, 1] = np.iinfo(np.int64).min
    boxes[:, 2] = np.iinfo(np.int64).max
    boxes[:, 3] = np.iinfo(np.int64).min
    for j in range(columns.shape[0]):
        r, c = rows[j], cols[j]
        for m in range(n_col):
            if columns[j, m] != 0.0:
                boxes[m, 0] = min(boxes[m, 0], r)
                boxes[m, 1] = max(boxes[m, 1], r)
                boxes[m, 2] = min(boxes[m, 2], c)
                boxes[m, 3] = max(boxes[m, 3], c)
    for m in range(n_col):
        if boxes[m, 1] < boxes[m, 0]:
            boxes[m, :] = (0, -1, 0, -1)
    return boxes


@njit(inline="always")
def _window_in_frame(origin, n_r, n_c, frame_shape):
    """Frame rows [r_lo, r_hi) and columns [c_lo, c_hi) of an n_r × n_c window whose
    top-left corner is at frame position ``origin``."""
    return (
        max(origin[0], 0),
        min(origin[0] + n_r, frame_shape[0]),
        max(origin[1], 0),
        min(origin[1] + n_c, frame_shape[1]),
    )


@njit(fastmath=True)
def _scatter_columns(columns, picked, origins, in_index, full_frame, stack):
    """stack[g] = column ``picked[g]`` of ``columns`` in its window, whose top-left corner
    is ``origins[g]`` in the frame whose pixels ``in_index`` numbers (−1: no input).

    Windows of the whole frame (``full_frame``, origins 0) are filled in one pass over
    the frame that reads each input's row of columns once; cropped windows one by one.
    """
    stack[:] = 0.0
    n_r, n_c = stack.shape[1], stack.shape[2]
    if full_frame:
        for r in range(in_index.shape[0]):
            for c in range(in_index.shape[1]):
                j = in_index[r, c]
                if j >= 0:
                    for g in range(picked.size):
                        stack[g, r, c] = columns[j, picked[g]]
        return
    for g in range(picked.size):
        m = picked[g]
        r_lo, r_hi, c_lo, c_hi = _window_in_frame(origins[g], n_r, n_c, in_index.shape)
        for r in range(r_lo, r_hi):
            for c in range(c_lo, c_hi):
                j = in_index[r, c]
                if j >= 0:
                    stack[g, r - origins[g, 0], c - origins[g, 1]] = columns[j, m]


@njit(fastmath=True)
def _gather_columns(full, picked, origins, out_index, full_frame, out):
    """out[p, picked[g]] = full[g] at output p's place in window g (as in
    :func:`_scatter_columns`); outputs outside a column's window keep their zero."""
    n_r, n_c = full.shape[1], full.shape[2]
    if full_frame:
        for r in range(out_index.shape[0]):
            for c in range(out_index.shape[1]):
                p = out_index[r, c]
                if p >= 0:
                    for g in range(picked.size):
                        out[p, picked[g]] = full[g, r, c]
        return
    for g in range(picked.size):
        m = picked[g]
        r_lo, r_hi, c_lo, c_hi = _window_in_frame(origins[g], n_r, n_c, out_index.shape)
        for r in range(r_lo, r_hi):
            for c in range(c_lo, c_hi):
                p = out_index[r, c]
                if p >= 0:
                    out[p, m] = full[g, r - origins[g, 0], c - origins[g, 1]]


CROP_GAIN = 0.7
"""A column is blurred in a window cropped to its nonzero inputs when the window's FFT has
at most this fraction of the full frame's pixels."""
PARALLEL_FFT_MIN_POINTS = 131_072
"""A batch of windows (columns × window pixels) is transformed on the job's threads from
this many points, smaller batches on one: starting scipy.fft's threads costs 0.1–0.5 ms
per transform, more than two threads save below about this size (docs/benchmarks.md,
"Small FFT batches on one thread")."""


@dataclass(frozen=True, eq=False)
class _FFTGeometry:
    """Frame and kernel spectra of the FFT route for one input region.

    The frame starts at the inputs' bounding box; its size per axis is the shortest fast
    length free of wrap-around at the outputs (:func:`wrap_free_length`). A column whose
    nonzero inputs fill a small part of it (e.g. a narrow Gaussian) is blurred in its own
    window instead: the box of those inputs grown by the kernel's half-widths, every
    output it can reach inside, at a fast length (a full linear convolution there).
    Kernels are stored rolled, so that output i of a circular convolution is the linear
    one's at input position i. The outputs must lie inside the inputs' bounding box (as
    the mask does in both input regions of :class:`Convolver`).
    """

    shape: tuple[int, int]
    half: tuple[int, int]
    psf: np.ndarray
    in_rows: np.ndarray
    in_cols: np.ndarray
    in_index: np.ndarray
    out_index: np.ndarray
    n_out: int
    spectra: dict

    @classmethod
    def build(cls, in_mask: np.ndarray, out_mask: np.ndarray, psf: np.ndarray) -> "_FFTGeometry":
        rows, cols = np.nonzero(~in_mask)
        out_rows, out_cols = np.nonzero(~out_mask)
        r0, c0 = rows.min(), cols.min()
        shape = []
        for axis, (start, inputs, outputs) in enumerate(
            ((r0, rows, out_rows), (c0, cols, out_cols))
        ):
            half = psf.shape[axis] // 2
            n = wrap_free_length(
                int(inputs.max() - start + 1),
                int(outputs.min() - start),
                int(outputs.max() - start),
                half,
            )
            shape.append(scipy.fft.next_fast_len(n, real=True))
        box = (rows.max() - r0 + 1, cols.max() - c0 + 1)
        in_index = np.full(box, -1, dtype=np.int64)
        in_index[rows - r0, cols - c0] = np.arange(rows.size)
        out_index = np.full(box, -1, dtype=np.int64)
        out_index[out_rows - r0, out_cols - c0] = np.arange(out_rows.size)
        return cls(
            shape=tuple(shape),
            half=(psf.shape[0] // 2, psf.shape[1] // 2),
            psf=psf,
            in_rows=(rows - r0).astype(np.int64),
            in_cols=(cols - c0).astype(np.int64),
            in_index=in_index,
            out_index=out_index,
            n_out=int(out_rows.size),
            spectra={},
        )

    def _spectrum(self, shape: tuple[int, int]) -> np.ndarray:
        if shape not in self.spectra:
            kernel = np.zeros(shape)
            ky, kx = self.psf.shape
            kernel[:ky, :kx] = self.psf
            kernel = np.roll(kernel, (-self.half[0], -self.half[1]), axis=(0, 1))
            self.spectra[shape] = scipy.fft.rfft2(kernel)
        return self.spectra[shape]

    def windows(self, columns: np.ndarray) -> dict:
        """{FFT shape: (column indices, window origins (n, 2))} of the nonzero columns."""
        boxes = _column_boxes(columns, self.in_rows, self.in_cols)
        full = self.shape[0] * self.shape[1]
        groups: dict = {}
        for m, (r_lo, r_hi, c_lo, c_hi) in enumerate(boxes):
            if r_hi < r_lo:
                continue  # an all-zero column blurs to zero
            shape = (
                scipy.fft.next_fast_len(int(r_hi - r_lo + 1 + 2 * self.half[0]), real=True),
                scipy.fft.next_fast_len(int(c_hi - c_lo + 1 + 2 * self.half[1]), real=True),
            )
            origin = (r_lo - self.half[0], c_lo - self.half[1])
            if shape[0] * shape[1] > CROP_GAIN * full:
                shape, origin = self.shape, (0, 0)
            picked, origins = groups.setdefault(shape, ([], []))
            picked.append(m)
            origins.append(origin)
        return {
            shape: (np.array(picked, dtype=np.int64), np.array(origins, dtype=np.int64))
            for shape, (picked, origins) in groups.items()
        }

    def blur(self, columns: np.ndarray, out: np.ndarray, at: np.ndarray) -> None:
        """Blur ``columns`` (n_in, n_col) into ``out[:, at]`` at the outputs (those columns
        of ``out`` zero on entry: outputs beyond a cropped column's window keep it)."""
        columns = np.ascontiguousarray(columns)
        threads = numba.get_num_threads()  # the job's threads (mgelens.threads policy)
        for shape, (picked, origins) in self.windows(columns).items():
            stack = np.empty((picked.size, *shape))
            workers = threads if stack.size >= PARALLEL_FFT_MIN_POINTS else 1
            full_frame = shape == self.shape
            _scatter_columns(columns, picked, origins, self.in_index, full_frame, stack)
            spectrum = scipy.fft.rfft2(stack, workers=workers, overwrite_x=True)
            spectrum *= self._spectrum(shape)[None]
            full = scipy.fft.irfft2(spectrum, s=shape, workers=workers, overwrite_x=True)
            _gather_columns(full, at[picked], origins, self.out_index, full_frame, out)


@dataclass(frozen=True)
class Convolver:
    """Blur columns defined on masked pixels and cut them back to the mask.

    Attributes
    ----------
    mask : ndarray of bool (n_y, n_x)
        Fit mask, True = excluded. Outputs are slim over its unmasked pixels (N_I).
    psf : ndarray (k_y, k_x)
        Odd, unit-sum PSF kernel.
    blurring_mask : ndarray of bool
        Pixels outside the mask whose light the PSF carries into it (False there).
    """

    mask: np.ndarray
    psf: np.ndarray
    blurring_mask: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "psf", check_psf(self.psf))
        object.__setattr__(self, "blurring_mask", blurring_mask(self.mask, self.psf.shape))

    @cached_property
    def extended_mask(self) -> np.ndarray:
        """Mask of the unmasked ∪ blurring-region pixels (False there)."""
        return self.mask & self.blurring_mask

    def input_mask(self, include_blurring: bool) -> np.ndarray:
        """Mask whose unmasked pixels are the inputs of ``blur_columns``."""
        return self.extended_mask if include_blurring else self.mask

    def operator(self, include_blurring: bool) -> sparse.csr_matrix:
        """Sparse direct-summation operator (N_I × n_in), built once per input region."""
        return self._operator_extended if include_blurring else self._operator_mask

    @cached_property
    def _operator_mask(self) -> sparse.csr_matrix:
        return psf_operator(self.mask, self.mask, self.psf)

    @cached_property
    def _operator_extended(self) -> sparse.csr_matrix:
        return psf_operator(self.extended_mask, self.mask, self.psf)

    @cached_property
    def _fft_geometries(self) -> dict:
        """:class:`_FFTGeometry` of each input region (by ``include_blurring``)."""
        return {
            blurring: _FFTGeometry.build(self.input_mask(blurring), self.mask, self.psf)
            for blurring in (True, False)
        }

    @cached_property
    def _separable_terms(self) -> tuple:
        return separable_terms(self.psf)

    @cached_property
    def _costs(self) -> dict[bool, dict[str, float]]:
        """Operation-count estimate of blurring one column by each method, per input
        region (by ``include_blurring``)."""
        n_terms = self._separable_terms[0].shape[0]
        costs = {}
        for blurring in (True, False):
            n_in = int(np.count_nonzero(~self.input_mask(blurring)))
            costs[blurring] = {
                "direct": _direct_cost(self.psf, n_in),
                "fft": _fft_cost(self._fft_geometries[blurring].shape),
                "separable": float(n_terms * sum(self.psf.shape)) * n_in,
            }
        return costs

    def column_cost(self, include_blurring: bool) -> float:
        """Estimated operations to blur one column by the method ``auto`` picks (about
        one multiply-add each for the direct and separable routes)."""
        return min(self._costs[include_blurring].values())

    def _method_for(self, include_blurring: bool, method: str) -> str:
        if method != "auto":
            return method
        costs = self._costs[include_blurring]
        return min(costs, key=costs.get)

    def blur_columns(
        self,
        columns: np.ndarray,
        include_blurring: bool = True,
        method: str = "auto",
        out: np.ndarray | None = None,
        at: np.ndarray | None = None,
    ) -> np.ndarray:
        """PSF-convolve each column and return them on the masked pixels.

        Parameters
        ----------
        columns : ndarray (n_in,) or (n_in, n_col)
            Values on the unmasked pixels of ``input_mask(include_blurring)``, slim order
            (zero is assumed everywhere else).
        include_blurring : bool
            True for light profiles (evaluated on mask ∪ blurring region), False for
            pixelized-source columns (mask only, SPEC §1.4).
        method : {"auto", "direct", "fft", "separable"}
        out, at : ndarray (N_I, m) and int ndarray (n_col,), optional
            Write the blurred 2D ``columns`` into ``out[:, at]`` (zero there on entry) and
            return ``out``, instead of a new array: callers that assemble columns from
            several routes then copy nothing.

        Returns
        -------
        ndarray (N_I,) or (N_I, n_col), or ``out``
        """
        columns = np.asarray(columns, dtype=float)
        vector = columns.ndim == 1
        if vector:
            columns = columns[:, None]
        in_mask = self.input_mask(include_blurring)
        if columns.shape[0] != np.count_nonzero(~in_mask):
            raise ValueError(
                f"columns have {columns.shape[0]} rows but the input region has "
                f"{np.count_nonzero(~in_mask)} pixels"
            )
        chosen = self._method_for(include_blurring, method)
        if chosen not in ("direct", "fft", "separable"):
            raise ValueError(f"unknown convolution method {method!r}")
        if out is None:
            if chosen == "fft":
                geometry = self._fft_geometries[include_blurring]
                blurred = np.zeros((geometry.n_out, columns.shape[1]))
                geometry.blur(columns, blurred, np.arange(columns.shape[1]))
            else:
                blurred = self._blur_by_sums(columns, include_blurring, chosen)
            return blurred[:, 0] if vector else blurred
        if chosen == "fft":
            self._fft_geometries[include_blurring].blur(columns, out, np.asarray(at))
        else:
            out[:, at] = self._blur_by_sums(columns, include_blurring, chosen)
        return out

    def _blur_by_sums(self, columns: np.ndarray, include_blurring: bool, method: str):
        """The direct or separable route's blurred ``columns``."""
        if method == "direct":
            return self.operator(include_blurring) @ columns
        return self._blur_separable(columns, include_blurring)

    def transpose_blur_columns(self, columns: np.ndarray) -> np.ndarray:
        """Bᵀ columns for the mask-to-mask operator B (``include_blurring=False``).

        B_ij = psf[r_i − r_j + h_y, c_i − c_j + h_x], so Bᵀ is the mask-to-mask operator
        of the PSF flipped in both axes and is computed by the same fast convolutions.
        ``columns`` (N_I,) or (N_I, n_col) are on the unmasked pixels; so is the result.
        """
        return self._flipped.blur_columns(columns, include_blurring=False)

    @cached_property
    def _flipped(self) -> "Convolver":
        return Convolver(self.mask, self.psf[::-1, ::-1].copy())

    @cached_property
    def _separable_geometries(self) -> dict:
        """:func:`_separable_geometry` of each input region (by ``include_blurring``)."""
        return {
            blurring: _separable_geometry(self.input_mask(blurring), self.mask, self.psf.shape)
            for blurring in (True, False)
        }

    def _blur_separable(self, columns: np.ndarray, include_blurring: bool) -> np.ndarray:
        geometry = self._separable_geometries[include_blurring]
        u, v = self._separable_terms
        return _separable_blur(np.ascontiguousarray(columns), *geometry, u, v)
