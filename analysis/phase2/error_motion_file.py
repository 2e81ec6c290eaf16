"""The ``error_motions.h5`` file that ``twin backlash`` writes beside ``backlash.json``: the
combined forward and reverse error motions of every Phase II session, read back by the scorer
and the Rerun view."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from analysis.base.files import atomic_write
from analysis.dataset import DOFS, DatasetError

__all__ = ["read_error_motion_bands", "read_error_motions", "write_error_motions"]


def write_error_motions(path: Path, ems) -> None:
    """Write the combined error motions of every session: group ``/<session>`` with ``x_m`` (n,)
    position in m (on the sessions' position axis, attribute
    ``position_reference``: "command" or "imu") and ``forward``, ``reverse`` (6, n) in m and rad (rows ``dofs``
    attribute), ``band_m`` (6, 2) the resolved wavelength band of each DOF in m (shortest,
    longest; NaN where none), attributes ``hours``, ``runs``. Read back by :func:`read_error_motions`."""
    def create(tmp: Path) -> None:
        with h5py.File(tmp, "w") as f:
            f.attrs["dofs"] = list(DOFS)
            f.attrs["position_reference"] = ems[0].position_reference if ems else "command"
            for em in ems:
                g = f.create_group(em.session)
                g.attrs["hours"] = em.hours
                g.attrs["runs"] = list(em.runs)
                g.create_dataset("x_m", data=em.combined.x_m)
                g.create_dataset("forward", data=em.combined.forward)
                g.create_dataset("reverse", data=em.combined.reverse)
                if em.combined.band_m is not None:
                    g.create_dataset("band_m", data=em.combined.band_m)

    atomic_write(path, create)


def read_error_motions(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The sessions of an ``error_motions.h5`` written by :func:`write_error_motions`:
    ``{session: (x_m (n,) m, forward (6, n), reverse (6, n))}``, rows in :data:`DOFS` order
    (m and rad) whatever order the file's ``dofs`` attribute gives.

    Raises:
        DatasetError: unreadable file, missing DOFs or inconsistent shapes (names file and key).
    """
    out = {}
    try:
        with h5py.File(path, "r") as f:
            dofs = [d.decode() if isinstance(d, bytes) else str(d) for d in f.attrs["dofs"]]
            missing = [d for d in DOFS if d not in dofs]
            if missing:
                raise DatasetError(f"{path}: /@dofs is {dofs}; expected all of {', '.join(DOFS)}")
            order = [dofs.index(d) for d in DOFS]
            for name, g in f.items():
                x = np.asarray(g["x_m"][...], dtype=np.float64)
                fwd = np.asarray(g["forward"][...], dtype=np.float64)
                rev = np.asarray(g["reverse"][...], dtype=np.float64)
                for key, arr in (("forward", fwd), ("reverse", rev)):
                    if x.ndim != 1 or len(x) < 2 or arr.shape != (len(dofs), len(x)):
                        raise DatasetError(
                            f"{path}: /{name}/{key} has shape {arr.shape} with x_m {x.shape}; "
                            f"expected ({len(dofs)}, n) with n = len(x_m) >= 2")
                out[name] = (x, fwd[order], rev[order])
    except (OSError, KeyError) as exc:
        raise DatasetError(f"{path}: cannot read the error motions ({exc}); rerun `twin backlash` "
                           "to rewrite it") from None
    return out


def read_error_motion_bands(path: Path) -> dict[str, np.ndarray | None]:
    """``{session: band_m (6, 2) m, rows in DOFS order}`` of an ``error_motions.h5``; None for a
    session written before the band was recorded. Raises :class:`DatasetError` as
    :func:`read_error_motions` does."""
    out: dict[str, np.ndarray | None] = {}
    try:
        with h5py.File(path, "r") as f:
            dofs = [d.decode() if isinstance(d, bytes) else str(d) for d in f.attrs["dofs"]]
            order = [dofs.index(d) for d in DOFS if d in dofs]
            for name, g in f.items():
                if "band_m" not in g:
                    out[name] = None
                    continue
                band = np.asarray(g["band_m"][...], dtype=np.float64)
                if band.shape != (len(dofs), 2) or len(order) != len(DOFS):
                    raise DatasetError(f"{path}: /{name}/band_m has shape {band.shape}; expected "
                                       f"({len(DOFS)}, 2) with every DOF in /@dofs")
                out[name] = band[order]
    except (OSError, KeyError) as exc:
        raise DatasetError(f"{path}: cannot read the error motions ({exc}); rerun `twin backlash` "
                           "to rewrite it") from None
    return out
