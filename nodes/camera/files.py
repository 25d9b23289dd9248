"""Stereo pairs from a folder of image files, with stamps from a CSV or from the file order at a rate.

Left and right images are two globs, sorted by name and paired in order. Stamps: a CSV with one stamp
(s) per pair in the same order — the first numeric column of each row; a non-numeric header row is
skipped — or, without a CSV, ``i / rate_hz``. Stamps are relative: :meth:`FileSource.stamps` returns them
as given, the camera node shifts them so the first pair maps to its start time (keeping the recorded
spacing).
"""

from __future__ import annotations

import csv
import glob

import cv2
import numpy as np

__all__ = ["FileSource"]


class FileSource:
    """Pairs from ``left_glob``/``right_glob`` (module doc). Raises ``ValueError`` when the globs match
    different or zero counts, the CSV row count differs, stamps decrease, or ``rate_hz`` is not positive."""

    def __init__(self, left_glob: str, right_glob: str, csv_path: str = "", rate_hz: float = 48.0):
        self.left = sorted(glob.glob(left_glob))
        self.right = sorted(glob.glob(right_glob))
        if not self.left or len(self.left) != len(self.right):
            raise ValueError(f"files_left matched {len(self.left)} files and files_right {len(self.right)}; "
                             "need the same non-zero count")
        if csv_path:
            with open(csv_path, newline="") as fh:
                st = []
                for row in csv.reader(fh):
                    if not row:
                        continue
                    try:
                        st.append(float(row[0]))
                    except ValueError:
                        if st:
                            raise ValueError(f"{csv_path}: non-numeric stamp {row[0]!r} after row "
                                             f"{len(st)}") from None
            if len(st) != len(self.left):
                raise ValueError(f"{csv_path}: {len(st)} stamps for {len(self.left)} pairs")
            self._stamps = np.asarray(st, float)
            if np.any(np.diff(self._stamps) < 0):
                raise ValueError(f"{csv_path}: stamps must not decrease")
        else:
            if not rate_hz > 0:
                raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
            self._stamps = np.arange(len(self.left)) / float(rate_hz)

    def __len__(self) -> int:
        return len(self.left)

    def stamps(self) -> np.ndarray:
        """Relative stamps (N,) s, non-decreasing."""
        return self._stamps.copy()

    def read(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Pair ``i`` as mono8 (left, right). Raises ``ValueError`` if a file cannot be read."""
        out = []
        for path in (self.left[i], self.right[i]):
            img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise ValueError(f"cannot read image {path!r}")
            out.append(img)
        return out[0], out[1]
