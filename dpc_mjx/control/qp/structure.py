"""The static nonzero pattern of G and the index tables the kernel multiplies by.

`solve(..., g_pattern=...)` takes a static (m, n) bool array saying which entries of G can be
nonzero (e.g. `balance.G_PATTERN`: 40 of 288). The kernel then stores and multiplies only those:
G x, G'y and the products G_ri G_rj that form H = P + G' diag(w) G. P and the Cholesky factor stay
dense. A `_Structure` (one per pattern, cached) holds the numpy index tables of these products; a
dense G is the pattern None, for which the kernel uses slices instead of gathers. A caller that
knows more of H's structure than G's pattern says adds its own factor of H (`solver`, normal.py).
docs/decisions-controller.md ("Low-level controller: the QP solver") explains the method.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from dpc_mjx.control.qp.ops import _UNROLL_MAX


@dataclasses.dataclass(frozen=True)
class _Structure:
    """The static nonzero pattern of G (m, n), or None for a dense G, with the index tables of
    the products the kernel forms from G's entries only (numpy, built once per pattern).

    Entries are addressed in G flattened row-major (r n + j); index m n is an appended zero,
    which pads the tables to rectangles.
    """

    m: int
    n: int
    pattern: tuple[tuple[bool, ...], ...] | None
    solver: object = None  # a normal.NormalSolver, or None: the kernel factors H itself

    @functools.cached_property
    def mask(self) -> np.ndarray:  # (m, n) bool
        if self.pattern is None:
            return np.ones((self.m, self.n), bool)
        return np.array(self.pattern, bool)

    def _padded(self, lists: list[list[int]]) -> np.ndarray:
        """Rows of flat entry indices padded with the zero entry to one width (>= 1)."""
        width = max(1, *(len(x) for x in lists))
        zero = self.m * self.n
        return np.array([x + [zero] * (width - len(x)) for x in lists], np.int64)

    @property
    def implicit_p(self) -> bool:
        """P reaches the kernel as a placeholder (0,): the normal solver knows it (normal.py)."""
        return self.solver is not None and self.solver.implicit_p

    @functools.cached_property
    def compact(self) -> bool:
        """G reaches the kernel as its pattern's entries (K,) (`entries`), not (m, n): a pattern
        of over `ops._UNROLL_MAX` variables (the MPC's G: 400 of 28,800 entries), so that no
        op of the kernel reads the whole G."""
        return self.pattern is not None and self.n > _UNROLL_MAX

    @functools.cached_property
    def entries(self) -> np.ndarray:
        """(K,) the flat indices r n + j of the pattern's entries, row-major."""
        return np.flatnonzero(self.mask)

    def at(self, flat: np.ndarray) -> np.ndarray:
        """Flat entry indices (m n: the zero) -> where the kernel reads them: the same in G
        flattened, or for a `compact` G their places among `entries` (K: the zero)."""
        if not self.compact:
            return flat
        where = np.full(self.m * self.n + 1, len(self.entries), np.int64)
        where[self.entries] = np.arange(len(self.entries))
        return where[flat]

    @functools.cached_property
    def rows(self) -> tuple[np.ndarray, np.ndarray]:
        """(m, K) flat entries of each row and (m, K) their columns (G x = sum_k of products)."""
        lists = [[r * self.n + j for j in np.flatnonzero(self.mask[r])] for r in range(self.m)]
        flat = self._padded(lists)
        return flat, flat % self.n * (flat < self.m * self.n)

    @functools.cached_property
    def cols(self) -> tuple[np.ndarray, np.ndarray]:
        """(n, L) flat entries of each column and (n, L) their rows (G'y = sum_l of products)."""
        lists = [[r * self.n + j for r in np.flatnonzero(self.mask[:, j])] for j in range(self.n)]
        flat = self._padded(lists)
        return flat, flat // self.n * (flat < self.m * self.n)

    @functools.cached_property
    def normal(self) -> list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray] | None]:
        """Per column j of H = G' diag(w) G: None if G' W G adds nothing to H[j:, j], else
        (lo, hi, a, b, r): entries j + lo .. j + hi - 1 get sum_t G[a_t] G[b_t] w[r_t], where
        a, b, r are (T, hi - lo) flat entries (padded with the zero entry) and rows."""
        out = []
        zero = self.m * self.n
        for j in range(self.n):
            terms = [np.flatnonzero(self.mask[:, i] & self.mask[:, j]) for i in range(j, self.n)]
            hit = [k for k, t in enumerate(terms) if len(t)]
            if not hit:
                out.append(None)
                continue
            lo, hi = hit[0], hit[-1] + 1
            width = max(len(terms[k]) for k in hit)
            a = np.full((width, hi - lo), zero, np.int64)
            b, r = a.copy(), np.zeros((width, hi - lo), np.int64)
            for k in range(lo, hi):
                t = terms[k]
                a[: len(t), k - lo] = t * self.n + j + k
                b[: len(t), k - lo] = t * self.n + j
                r[: len(t), k - lo] = t
            out.append((lo, hi, a, b, r))
        return out

    @functools.cached_property
    def normal_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """(K,) rows and (K,) columns of the entries of H that G' diag(w) G adds to, column by
        column as in `normal` (column j: rows j + lo .. j + hi - 1)."""
        spans = [(j, s[0], s[1]) for j, s in enumerate(self.normal) if s is not None]
        rows = [np.arange(j + lo, j + hi) for j, lo, hi in spans]
        cols = [np.full(hi - lo, j) for j, lo, hi in spans]
        empty = np.zeros(0, np.int64)
        return np.concatenate([empty, *rows]), np.concatenate([empty, *cols])


@functools.lru_cache(maxsize=None)
def _structure(
    m: int, n: int, pattern: tuple[tuple[bool, ...], ...] | None, solver: object = None
) -> _Structure:
    return _Structure(m, n, pattern, solver)
