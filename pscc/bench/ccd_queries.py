"""Reader of the CCD query benchmark shipped in ``tests/data/ccd-queries`` (exact rational coordinates).

Each CSV row is ``num_x, den_x, num_y, den_y, num_z, den_z, truth``; 8 rows form one query
(4 points at t = 0, then the same 4 at t = 1). See that folder's README and LICENSE.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from pscc.errors import InputError


@dataclass(frozen=True)
class QuerySet:
    """One scene's queries of one kind.

    Attributes:
        name: ``<scene>/<vertex-face|edge-edge>``.
        points_t0: (n, 4, 3) float64 (the nearest doubles of the exact rationals).
        points_t1: (n, 4, 3) float64.
        truth: (n,) bool exact answer.
    """

    name: str
    points_t0: np.ndarray
    points_t1: np.ndarray
    truth: np.ndarray

    @property
    def kind(self) -> str:
        """``vertex-face`` or ``edge-edge``."""
        return self.name.rsplit("/", 1)[1]


def default_root() -> Path:
    """``tests/data/ccd-queries`` of the source checkout."""
    return Path(__file__).resolve().parents[2] / "tests" / "data" / "ccd-queries"


def load_query_sets(root: Path | None = None) -> list[QuerySet]:
    """Read every ``<scene>/<kind>/*.csv`` under ``root`` (default :func:`default_root`)."""
    root = Path(root) if root is not None else default_root()
    if not root.is_dir():
        raise InputError(str(root), "ccd-queries", "the query folder does not exist",
                         "run from a source checkout that has tests/data/ccd-queries")
    sets = []
    for folder in sorted(p for p in root.glob("*/*") if p.is_dir()):
        coords: list[list[float]] = []
        truth: list[int] = []
        for path in sorted(folder.glob("*.csv")):
            for line in path.read_text().splitlines():
                n = [int(x) for x in line.split(",")]
                coords.append([float(Fraction(n[0], n[1])), float(Fraction(n[2], n[3])),
                               float(Fraction(n[4], n[5]))])
                truth.append(n[6])
        points = np.array(coords, dtype=np.float64).reshape(-1, 8, 3)
        sets.append(QuerySet(
            name=f"{folder.parent.name}/{folder.name}",
            points_t0=points[:, :4],
            points_t1=points[:, 4:],
            truth=np.array(truth).reshape(-1, 8)[:, 0].astype(bool),
        ))
    return sets
