"""Each camera capture's pose corrected from the touches: a bounded rigid alignment that knows the cover's gap.

A depth camera's calibrated pose is off by a few millimetres and about a degree; a metre away that moves the seen
cover by 1-2 cm, as much as the gap between a tight cover and the body. The touches say where the body is. Each
contact lies on the inner surface, each capture's points on the outer one, a gap ``g`` off it along the cover's
normal; where two captures see the same cover they must agree with each other. :func:`correct_captures` finds, for
every capture ``k``, the rigid motion about its optical centre ``c_k``

    ``T_k(q) = c_k + R(w_k) (q - c_k) + t_k``

and one gap ``g`` that minimise, over the contacts under each capture's seen cover and the points where two captures
overlap,

    ``sum_i rho(m_i . (T_k(q_i) - p_i) - g) + sum_j rho(m_j . (T_k(q_j) - T_l(q'_j)))
    + |t_k|^2 / s_t^2 + |w_k|^2 / s_w^2``

(``p_i`` a contact, ``q_i`` the capture's nearest point and ``m_i`` its normal there, towards the camera; ``rho`` the
Huber loss; each residual in its standard deviation: the overlaps' measured at each iteration from their spread, and
each pair counted as one :data:`PATCH`-th of one, since neighbouring planes share their points), by Gauss-Newton with
correspondences found again at each iteration (point-to-plane ICP). The prior's
scales ``s_t``, ``s_w`` are half the largest error the user says a calibration can have, and no correction goes beyond
that bound (it is scaled back onto it and said).

Written here rather than taken from a registration library (Open3D's ICP, probreg): those align two clouds; this
aligns several captures to contacts that lie a gap behind the surface they see, estimates that gap with them, and
bounds each correction.

A camera that rides on the arm (a wrist camera) is off by one error for every capture: its hand-eye transform's, fixed
in the frame of the link it is mounted on. With ``mount`` (each capture's pose of that link), the captures share one
correction ``D`` in the mount's frame, and capture ``k`` moves by ``M_k D M_k^-1`` (``M_k`` the mount's pose when it
was taken): the same residuals, six unknowns instead of six per capture (an exact reparameterisation: the rotation of
``D`` seen from the base is ``R(A_k w) = A_k R(w) A_k^T``).

What the contacts can tell depends on where they are: contacts on one flat face fix the translation along its normal
together with the gap, and nothing along the face. The Gauss-Newton curvature says which directions the data fix;
:attr:`CaptureCorrection.weak` names those left to the prior.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..core.validation import as_float
from .pointcloud import rigid_about, rotation_matrix, skew

__all__ = ["CaptureCorrection", "CaptureCorrections", "correct_captures", "misfit_text"]

#: Huber threshold of the residuals, in their standard deviations: a contact or overlap further off counts linearly
#: (a wrong correspondence, a fold of the cover, an edge).
HUBER = 2.0
#: A contact and a capture's surface (or two captures' surfaces) pair only where their normals agree this well (the
#: cosine of about 37 degrees).
FACING = 0.8
#: Contacts under the seen cover (over all captures) below which no capture is corrected.
MIN_CONTACTS = 5
#: ... unless every capture has at least this many points on the known support plane (``correct_captures``'
#: ``support``): the table alone fixes each capture's height and its rotations about horizontal axes, and the prior
#: holds the rest.
MIN_SUPPORT = 100
#: The gap's prior scale [m]: flat about none (the contacts fix the gap; the prior only keeps the system solvable).
GAP_SCALE = 0.05
#: A direction of a capture's correction is "weak" when the data's curvature along it is below this share of the
#: prior's: the prior, not the touches, set it.
WEAK = 1.0
#: Points per local plane of a capture (:func:`_local_planes`): each plane's centre and normal average its point's
#: nearest this many.
PATCH = 12
#: The least spread [m] a measured ``overlap_sigma`` takes (two noiseless renderings of one surface agree exactly).
PAIR_FLOOR = 0.0002


@dataclass(frozen=True)
class CaptureCorrection:
    """The rigid correction of one capture (base frame): ``q -> origin + R(rotation) (q - origin) + translation``.

    Attributes:
        translation: `(3,)` [m].
        rotation: `(3,)` rotation vector [rad].
        origin: `(3,)` the optical centre it turns about [m].
        contacts: the contacts that lay under this capture's seen cover at the end (they fixed it).
        overlap: the points where it overlaps another capture at the end.
        at_bound: the correction reached the bound and was scaled back onto it.
        weak: the directions the data left to the prior ("x", "y", "z" of the translation; "rx", "ry", "rz" of the
            rotation, base frame).
        support: the capture's points on the known support plane that took part (``correct_captures``' ``support``;
            0 without one).
    """

    translation: np.ndarray
    rotation: np.ndarray
    origin: np.ndarray
    contacts: int = 0
    overlap: int = 0
    at_bound: bool = False
    weak: tuple = ()
    support: int = 0

    @classmethod
    def from_record(cls, record: dict) -> "CaptureCorrection":
        """The correction :meth:`as_record` wrote (to its rounding: 1 um, 1e-4 degree)."""
        return cls(np.asarray(record["translation_mm"], dtype=np.float64) / 1e3,
                   np.radians(np.asarray(record["rotation_deg"], dtype=np.float64)),
                   np.asarray(record["origin"], dtype=np.float64), int(record.get("contacts", 0)),
                   int(record.get("overlap", 0)), bool(record.get("at_bound", False)), tuple(record.get("weak", ())),
                   int(record.get("support", 0)))

    @property
    def size(self) -> float:
        """|translation| [m]."""
        return float(np.linalg.norm(self.translation))

    @property
    def angle(self) -> float:
        """The rotation's angle [rad]."""
        return float(np.linalg.norm(self.rotation))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """`(n, 3)` ``points`` [m] moved by the correction."""
        return rigid_about(points, self.origin, self.rotation, self.translation)

    def through(self, pose: np.ndarray) -> "CaptureCorrection":
        """This correction, given in a mount's frame, as the frame ``pose`` places it sees it (``pose``: `(4, 4)`
        ``T_frame_mount``, e.g. the flange in the base frame when a wrist camera took a capture): the same motion,
        ``M D M^-1``, about the origin moved with it."""
        A, a = np.asarray(pose, dtype=np.float64)[:3, :3], np.asarray(pose, dtype=np.float64)[:3, 3]
        return dataclasses.replace(self, translation=A @ self.translation, rotation=A @ self.rotation,
                                   origin=a + A @ self.origin)

    def as_record(self) -> dict:
        """For records and ``fit.json``: the correction in mm and degrees about ``origin`` [m], its sizes, what fixed
        it (:meth:`from_record` reads it back)."""
        return {"translation_mm": (np.asarray(self.translation) * 1e3).round(3).tolist(),
                "rotation_deg": np.degrees(self.rotation).round(4).tolist(),
                "origin": np.asarray(self.origin, dtype=np.float64).round(6).tolist(),
                "size_mm": round(self.size * 1e3, 3), "angle_deg": round(math.degrees(self.angle), 4),
                "contacts": self.contacts, "overlap": self.overlap, "at_bound": self.at_bound,
                "weak": list(self.weak), **({"support": self.support} if self.support else {})}


@dataclass(frozen=True)
class CaptureCorrections:
    """What :func:`correct_captures` found.

    Attributes:
        captures: one :class:`CaptureCorrection` per capture, in order.
        gap: the cover's gap the contacts show once the captures are corrected [m] (NaN: no contact counted).
        before: the contacts' root-mean-square misfit under the captures as given [m] (their distance along the
            cover's normal, less the gap fitted to them as given; where none lies at about that gap, those within
            what the bound allows, less their median or the gap given; NaN: no contact under any seen cover, or a
            single one with the gap estimated, whose misfit about its own distance says nothing).
        after: the same once corrected [m].
        bound: ``(translation [m], rotation [rad])``, the largest correction allowed.
        mount: with ``correct_captures(mount=...)``, the one correction of the camera's mount, in the mount's frame
            about the camera's optical centre there (its ``weak`` directions in that frame); None otherwise.
        enough: whether at least :data:`MIN_CONTACTS` contacts lay under the seen cover (over all captures) at the
            end, or every capture held :data:`MIN_SUPPORT` points to a known support plane; when not, every
            correction is none (the captures as given): a handful of contacts pulls the captures where they fit
            best, not where they belong.
    """

    captures: list
    gap: float
    before: float
    after: float
    bound: tuple = field(default=(0.0, 0.0))
    enough: bool = True
    mount: CaptureCorrection | None = None

    def as_record(self) -> dict:
        """For records and ``fit.json``: each capture's correction, the gap, the misfits before and after (None
        where no contact was under the seen cover to measure it), the bound, and the mount's correction if any."""
        return {"captures": [c.as_record() for c in self.captures],
                "gap_mm": None if not math.isfinite(self.gap) else round(self.gap * 1e3, 3),
                "misfit_before_mm": _mm(self.before), "misfit_after_mm": _mm(self.after),
                "enough": self.enough,
                "bound": {"translation_mm": round(self.bound[0] * 1e3, 3),
                          "rotation_deg": round(math.degrees(self.bound[1]), 4)},
                **({"mount": self.mount.as_record()} if self.mount is not None else {})}

    def warnings(self, names=None, large: float = 0.5) -> list[str]:
        """Lines for the user: each capture whose correction is more than ``large`` of the bound, or at it.

        Args:
            names: a name per capture (file names); default "capture k". With a mount, one name for the camera.
            large: the share of the bound beyond which a correction is worth a word.
        """
        out = []
        if self.mount is not None:      # one camera, one correction: said once, of its hand-eye transform
            listed = [(names[0] if names else "the camera on its mount", self.mount)]
        else:
            listed = [(names[k] if names is not None else f"capture {k}", c) for k, c in enumerate(self.captures)]
        for name, c in listed:
            share = max(c.size / self.bound[0] if self.bound[0] else 0.0, c.angle / self.bound[1] if self.bound[1]
                        else 0.0)
            if c.at_bound or share > large:
                what = "its hand-eye calibration" if self.mount is not None else "the camera's calibration"
                out.append(f"{name} moved {c.size * 1e3:.1f} mm and {math.degrees(c.angle):.2f} deg to agree with "
                           f"the touches{' (the most allowed)' if c.at_bound else ''}: check {what}")
        return out


def _mm(value: float) -> float | None:
    """A length [m] in mm for a record, None where it was not measured (NaN: JSON has no NaN)."""
    return round(value * 1e3, 3) if math.isfinite(value) else None


def misfit_text(record: dict) -> str:
    """``"the contacts' misfit 3.0 -> 0.8 mm"`` from a :meth:`CaptureCorrections.as_record` (older records' NaN
    and this one's None: "not measured", where no contact lay under the seen cover as the calibration placed it, or a
    single one with the gap estimated)."""
    def mm(v) -> str:
        return "not measured" if v is None or not math.isfinite(v) else f"{v:.1f}"

    before, after = record.get("misfit_before_mm"), record.get("misfit_after_mm")
    return f"the contacts' misfit {mm(before)} -> {mm(after)} mm"


def _local_planes(points: np.ndarray, origin: np.ndarray, neighbours: int = PATCH) -> tuple[np.ndarray, np.ndarray]:
    """`(n, 3)` centres and unit normals of the planes through each capture point's nearest neighbours, the normals
    turned towards the camera (the cover's outside). The centre, not the point: a depth camera's noise (3 mm at a
    metre) averaged over the patch."""
    from scipy.spatial import cKDTree

    k = min(neighbours, len(points))
    _, idx = cKDTree(points).query(points, k=k)
    centre = points[idx].mean(axis=1)
    normal = np.linalg.svd(points[idx] - centre[:, None])[2][:, -1]
    flip = ((origin - centre) * normal).sum(axis=1) < 0
    normal[flip] *= -1
    return centre, normal


def _huber_weights(r: np.ndarray, delta: float) -> np.ndarray:
    a = np.abs(r)
    return np.where(a <= delta, 1.0, delta / np.maximum(a, 1e-300))


def _consensus_shift(q: np.ndarray, m: np.ndarray, tree, p: np.ndarray, nrm: np.ndarray | None, far: float,
                     reach: float, gap: float | None) -> tuple[np.ndarray, float, int, int]:
    """The translation of one capture (and the gap) that puts the most contacts under its seen cover at the gap: a
    grid of shifts ``reach`` apart within ``far`` on every axis, each with the gap that counts most (1 mm steps up to
    ``far``; or ``gap`` when given); ties go to the smaller shift. Gauss-Newton from no shift stops in the first
    minimum it meets (a face's contacts paired with the next face when the error is larger than the gap); this is
    its start. Returns the shift `(3,)` [m], its gap [m], its count and the count with no shift."""
    n = int(math.ceil(far / reach))
    axis = np.arange(-n, n + 1) * reach
    shifts = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    moved = p[None, :, :] - shifts[:, None, :]               # the contacts against the shifted capture
    d, j = tree.query(moved.reshape(-1, 3))
    d, j = d.reshape(len(shifts), len(p)), j.reshape(len(shifts), len(p))
    off = ((q[j] - moved) * m[j]).sum(axis=2)
    along = np.sqrt(np.maximum(d ** 2 - off ** 2, 0.0))
    ok = along <= reach
    if nrm is not None:
        ok &= (m[j] * nrm[None]).sum(axis=2) > FACING
    gaps = np.array([gap]) if gap is not None else np.arange(0.0, far + 1e-12, 0.001)
    tol = reach / 2
    counts = ((np.abs(off[:, :, None] - gaps[None, None, :]) <= tol) & ok[:, :, None]).sum(axis=1)   # (shifts, gaps)
    best = counts.max(axis=1)
    size = np.linalg.norm(shifts, axis=1)
    pick = int(np.lexsort((size, -best))[0])
    none = int(np.argmin(size))
    return shifts[pick], float(gaps[int(np.argmax(counts[pick]))]), int(best[pick]), int(best[none])


def correct_captures(captures, contacts, normals=None, *, max_translation: float, max_rotation: float,
                     reach: float = 0.006,
                     overlap_reach: float = 0.01, sample: int = 1500, iterations: int = 25,
                     gap: float | None = None, seed: int = 0, contact_sigma: float = 0.0025,
                     overlap_sigma: float | None = None, support=None, support_sigma: float = 0.003,
                     support_sample: int = 300, mount=None) -> CaptureCorrections:
    """Correct each capture's pose from the contacts and the other captures (see the module docstring).

    Why this many parameters: beside the bound (the one a user must give), each is a robust weight or a sample size
    with a measured default, kept reachable for a camera unlike the simulated ones.

    Args:
        captures: :class:`~torch_gpioius.sensors.pointcloud.PointCloud` objects with their camera's ``origin`` (a
            capture without one turns about its points' centre), base frame [m].
        contacts: `(m, 3)` contacts on the inner surface [m], base frame.
        normals: `(m, 3)` the body's outward normal at each contact (a fingertip's force direction), or None. With
            them a contact counts under a capture only where the capture's surface faces the same way (within
            :data:`FACING`): a contact on a side the camera did not see is otherwise paired with the nearest seen
            face across an edge.
        max_translation: the largest translation a calibration can be off by [m] (> 0).
        max_rotation: the largest rotation [rad] (> 0).
        reach: a contact counts under a capture where its foot on the plane of the capture's nearest point lies
            within this [m] of that point (the camera saw the cover right above it, not past its seen edge) and its
            distance along the plane's normal is within this of the gap; that distance's window starts from what the
            bound can move the captures by (a degree a metre away: 17 mm) and narrows to this.
        overlap_reach: two captures overlap where their points lie within this [m].
        sample: at most this many points of each capture take part (evenly chosen, seeded).
        iterations: Gauss-Newton iterations, each with its correspondences found again.
        gap: the cover's gap [m] if known (held); None: estimated with the corrections.
        seed: the sampling's seed.
        contact_sigma: a contact's misfit [m] beyond the captures' errors: how far it lies from the body's surface
            (a fingertip pressed 1-3 mm in), the cover's sag, the estimate's normal there.
        overlap_sigma: the misfit of two captures' planes where they overlap [m], or None (default): measured at
            each iteration, the pairs' robust spread (1.48 times their median absolute misfit; at least
            :data:`PAIR_FLOOR`), which follows the cameras' own depth noise (1.3 mm on the simulated Kinect views of
            the object sets a metre away, a few tenths of one on a wrist camera's close clouds). Neighbouring planes
            share most of their points, so their pairs are far from independent: each counts as one
            :data:`PATCH`-th of a pair (its standard deviation times ``sqrt(PATCH)``). Counted as independent with
            1 mm, a thousand pairs outweighed twenty contacts hundreds of times over, and the far views' noise
            turned calibrated captures by 0.3-0.4 degree about the vertical.
        support: ``(normal (3,), offset)``, the plane ``normal . x = offset`` [m] the object stands on, known in the
            base frame, or the height [m] of a horizontal one (a table whose height the robot measured, z up): each
            capture's points on it
            (``PointCloud.support``) are held to it as well, which fixes the two rotations about horizontal axes
            and the height that the contacts on a body's few faces leave loose. None: no plane.
        support_sigma: a support point's misfit [m] beyond the capture's error (its depth noise, the table's
            flatness).
        support_sample: at most this many support points of each capture take part (evenly chosen, seeded).
        mount: `(K, 4, 4)` the pose ``T_base_mount`` of the link the camera rides on when each capture was taken (a
            wrist camera's flange), or None. With it the captures share one correction, the camera's hand-eye error
            in the mount's frame (:attr:`CaptureCorrections.mount`), and each capture moves by it as seen from the
            base then; the bound is the mount's. None: each capture its own correction (fixed cameras).

    Returns:
        :class:`CaptureCorrections`.

    Raises:
        ValueError: no captures, bad shapes, non-finite values, a bound or an ``overlap_sigma`` that is not
            positive, or a mount pose that is not a rigid transform.
    """
    from scipy.spatial import cKDTree

    captures = list(captures)
    p = np.asarray(contacts, dtype=np.float64).reshape(-1, 3) if np.size(contacts) else np.zeros((0, 3))
    if not captures:
        raise ValueError("correct_captures: no captures")
    if not np.isfinite(p).all():
        raise ValueError("correct_captures: contacts must be finite (m, 3) points [m]")
    nrm = None
    if normals is not None:
        nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3) if np.size(normals) else np.zeros((0, 3))
        length = np.linalg.norm(nrm, axis=1, keepdims=True)
        if nrm.shape != p.shape or not np.isfinite(nrm).all() or (length == 0).any():
            raise ValueError(f"correct_captures: normals must be finite non-zero {p.shape} directions, one per "
                             f"contact, got shape {nrm.shape}")
        nrm = nrm / length
    for name, v in (("max_translation", max_translation), ("max_rotation", max_rotation)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise ValueError(f"correct_captures: {name} must be a positive bound, got {v!r}")
    if overlap_sigma is not None:               # None: measured from the pairs' spread
        overlap_sigma = as_float(overlap_sigma, "correct_captures: overlap_sigma", positive=True, unit="m")
    plane = None
    if support is not None:
        if isinstance(support, (int, float)) and not isinstance(support, bool):
            support = ((0.0, 0.0, 1.0), support)             # a table's height: the horizontal plane z = support
        try:
            pn, po = np.asarray(support[0], dtype=np.float64).reshape(3), float(support[1])
        except (TypeError, ValueError, IndexError) as exc:
            raise ValueError(f"correct_captures: support must be (normal (3,), offset), got {support!r}") from exc
        if not (np.isfinite(pn).all() and math.isfinite(po) and np.linalg.norm(pn) > 0):
            raise ValueError("correct_captures: support must be a finite plane with a non-zero normal, got "
                             f"{support!r}")
        plane = (pn / np.linalg.norm(pn), po / np.linalg.norm(pn))
    rng = np.random.default_rng(seed)
    pts, origins, faces = [], [], []   # each capture's plane centres, camera, plane normals
    for k, cap in enumerate(captures):
        q = np.asarray(cap.points, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != 3 or len(q) < 10 or not np.isfinite(q).all():
            raise ValueError(f"correct_captures: capture {k} needs at least 10 finite (n, 3) points")
        o = np.asarray(cap.origin, dtype=np.float64) if cap.origin is not None else None
        if o is not None and o.ndim == 2:           # a merged capture: its first camera's origin
            o = o[np.isfinite(o).all(axis=1)][0] if np.isfinite(o).all(axis=1).any() else None
        o = q.mean(axis=0) if o is None else o.reshape(3)
        q, n = _local_planes(q, o)
        if len(q) > sample:
            pick = np.sort(rng.choice(len(q), sample, replace=False))
            q, n = q[pick], n[pick]
        pts.append(q)
        origins.append(o)
        faces.append(n)
    # each capture's points on the support plane (drawn after the object's, so that those are as without a plane)
    table = [np.zeros((0, 3))] * len(captures)
    if plane is not None:
        for k, cap in enumerate(captures):
            sp = getattr(cap, "support", None)
            if sp is not None and len(sp):
                sp = np.asarray(sp, dtype=np.float64).reshape(-1, 3)
                table[k] = sp[np.sort(rng.choice(len(sp), support_sample, replace=False))] \
                    if len(sp) > support_sample else sp
    K = len(captures)
    mounted = _mount_poses(mount, K)
    # Each capture moves about its points' middle (the pivot d = pivot - c from its camera): q -> pivot + R (q - pivot)
    # + u. About the optical centre a metre away, a degree and 17 mm of translation are nearly the same motion at the
    # object, and Gauss-Newton crawls along that valley; about the object they are separate. The calibration's prior
    # (t ~ N(0, s_t^2), w ~ N(0, s_w^2) about the optical centre) becomes, with u = t - [d]x w, a 6x6 Gaussian on
    # (u, w); the answer goes back to the optical centre exactly: t = u + (I - R) d.
    s_t, s_w = max_translation / 2.0, max_rotation / 2.0
    pivots = [q.mean(axis=0) for q in pts]
    prior = np.zeros((6 * K + 1, 6 * K + 1))
    for k in range(K):
        D = skew(pivots[k] - origins[k])
        cov = np.block([[s_t ** 2 * np.eye(3) + s_w ** 2 * D @ D.T, -s_w ** 2 * D],
                        [-s_w ** 2 * D.T, s_w ** 2 * np.eye(3)]])
        prior[6 * k:6 * k + 6, 6 * k:6 * k + 6] = np.linalg.inv(cov)
    # the gap: a flat prior of 5 cm about none (the contacts fix it; the prior only keeps the system solvable when no
    # contact lies under any seen cover)
    prior[-1, -1] = 1.0 / GAP_SCALE ** 2
    x = np.zeros(6 * K + 1)                        # (u_k, w_k) per capture, then the gap
    fixed_gap = gap is not None
    if mounted is not None:
        # one camera on a moving link: the unknowns are its correction in the mount's frame, y = (u, w, gap), about a
        # pivot there; capture k's are x_k = (A_k u, A_k w) about the pivot as the mount then placed it (exact)
        A, a = mounted[:, :3, :3], mounted[:, :3, 3]
        camera_m = np.mean([(origins[k] - a[k]) @ A[k] for k in range(K)], axis=0)
        pivot_m = np.mean([(pts[k].mean(axis=0) - a[k]) @ A[k] for k in range(K)], axis=0)
        pivots = [a[k] + A[k] @ pivot_m for k in range(K)]
        lift = np.zeros((6 * K + 1, 7))
        for k in range(K):
            lift[6 * k:6 * k + 3, 0:3] = A[k]
            lift[6 * k + 3:6 * k + 6, 3:6] = A[k]
        lift[-1, -1] = 1.0
        D = skew(pivot_m - camera_m)
        prior_y = np.zeros((7, 7))
        prior_y[:6, :6] = np.linalg.inv(np.block([[s_t ** 2 * np.eye(3) + s_w ** 2 * D @ D.T, -s_w ** 2 * D],
                                                  [-s_w ** 2 * D.T, s_w ** 2 * np.eye(3)]]))
        prior_y[-1, -1] = prior[-1, -1]

    def moved(k: int, xv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        R = rotation_matrix(xv[6 * k + 3:6 * k + 6])
        return pivots[k] + (pts[k] - pivots[k]) @ R.T + xv[6 * k:6 * k + 3], faces[k] @ R.T, R

    def terms(xv: np.ndarray, reach_now: float = reach):
        """Rows (jacobian, residual, standard deviation) of the contacts, the support plane and the overlaps at
        ``xv``; the counts per capture; which rows are the overlaps' pairs (their standard deviation
        ``overlap_sigma`` times ``sqrt(PATCH)``, or 1 where it is measured: set by the caller)."""
        n = 6 * K + 1
        J, r, sd, counts, overlaps = [np.zeros((0, n))], [np.zeros(0)], [np.zeros(0)], [0] * K, [0] * K
        pairs = [np.zeros(0, dtype=bool)]
        g = xv[-1]
        cur = [moved(k, xv) for k in range(K)]
        for k, (_, _, R) in enumerate(cur):
            if len(table[k]):                   # on the known plane: n . (pivot + R (q - pivot) + u) = offset
                arm = (table[k] - pivots[k]) @ R.T
                rows = np.zeros((len(arm), n))
                rows[:, 6 * k:6 * k + 3] = plane[0]
                rows[:, 6 * k + 3:6 * k + 6] = np.cross(arm, plane[0])
                J.append(rows)
                r.append((pivots[k] + arm + xv[6 * k:6 * k + 3]) @ plane[0] - plane[1])
                sd.append(np.full(len(arm), support_sigma))
                pairs.append(np.zeros(len(arm), dtype=bool))
        for k, (q, m, _) in enumerate(cur):
            arm = q - pivots[k] - xv[6 * k:6 * k + 3]                      # R (q0 - pivot): what the rotation turns
            if len(p):
                d, j = cKDTree(q).query(p)
                off = ((q[j] - p) * m[j]).sum(axis=1)                     # along the cover's normal
                along = np.sqrt(np.maximum(d ** 2 - off ** 2, 0.0))
                # under the seen cover (its foot near a seen point: never past the seen edge, whatever the error),
                # at about the gap from it (from what the bound allows down to ``reach``)
                use = (along <= reach) & (np.abs(off - g) <= reach_now)
                if nrm is not None:
                    use &= (m[j] * nrm).sum(axis=1) > FACING
                jj = j[use]
                rows = np.zeros((len(jj), n))
                rows[:, 6 * k:6 * k + 3] = m[jj]
                rows[:, 6 * k + 3:6 * k + 6] = np.cross(arm[jj], m[jj])
                rows[:, -1] = -1.0
                J.append(rows)
                r.append(off[use] - g)
                sd.append(np.full(len(jj), contact_sigma))
                pairs.append(np.zeros(len(jj), dtype=bool))
                counts[k] = int(use.sum())
            for other in range(k + 1, K):
                q2, m2, _ = cur[other]
                d, j = cKDTree(q2).query(q, distance_upper_bound=max(overlap_reach, reach_now))
                hit = np.isfinite(d)
                hit[hit] = (m[hit] * m2[j[hit]]).sum(axis=1) > FACING
                i, jj = np.flatnonzero(hit), j[hit]
                mm = m2[jj]
                arm2 = q2[jj] - pivots[other] - xv[6 * other:6 * other + 3]
                rows = np.zeros((len(i), n))
                rows[:, 6 * k:6 * k + 3] = mm
                rows[:, 6 * k + 3:6 * k + 6] = np.cross(arm[i], mm)
                rows[:, 6 * other:6 * other + 3] = -mm
                rows[:, 6 * other + 3:6 * other + 6] = -np.cross(arm2, mm)
                J.append(rows)
                r.append(((q[i] - q2[jj]) * mm).sum(axis=1))
                sd.append(np.full(len(i), 1.0 if overlap_sigma is None else overlap_sigma * math.sqrt(PATCH)))
                pairs.append(np.ones(len(i), dtype=bool))
                overlaps[k] += len(i)
                overlaps[other] += len(i)
        return np.concatenate(J), np.concatenate(r), np.concatenate(sd), counts, overlaps, np.concatenate(pairs)

    def contact_misfit(xv: np.ndarray, reach_now: float = reach) -> tuple[float, float]:
        """The contacts' rms misfit and their median distance (the gap) under the captures at ``xv``, those within
        ``reach_now`` of the gap counted. The misfit is NaN (not measured) where no contact counts, and where a single
        one does and the gap is estimated (its misfit about its own distance is 0 whatever the captures' error)."""
        J, r, _, _, _, _ = terms(xv, reach_now)
        rows = J[:, -1] == -1.0
        if not rows.any():
            return math.nan, math.nan
        off = r[rows] + xv[-1]
        g = xv[-1] if fixed_gap else float(np.median(off))
        if len(off) < 2 and not fixed_gap:
            return math.nan, g
        return float(np.sqrt(np.mean((off - g) ** 2))), g

    if fixed_gap:
        x[-1] = float(gap)
    before, g0 = contact_misfit(x)
    x[-1] = float(gap) if fixed_gap else (g0 if math.isfinite(g0) else 0.0)
    H = prior.copy()
    # how far the bound can move a capture at the object: an error of 6 mm and a degree moves the seen cover 1-2.5 cm,
    # beyond a tight cover's gap
    far = max(reach, max_translation + max_rotation * max(np.linalg.norm(pv - o) for pv, o in zip(pivots, origins)))
    if not math.isfinite(before) and len(p):
        # no contact at about the gap under the cover as given (a gap wider than ``reach``, or the error moved the
        # cover): the misfit as given among the contacts within what the bound allows beyond any gap up to the gap's
        # prior scale (5 cm), about their own median
        before = contact_misfit(x, far + GAP_SCALE)[0]
    if len(p):
        starts = [_consensus_shift(pts[k], faces[k], cKDTree(pts[k]), p, nrm, far, reach,
                                   float(gap) if fixed_gap else None) for k in range(K)]
        gaps, weights, shifts = [], [], []
        for k, (shift, g_k, count, count0) in enumerate(starts):
            if count >= 5 and count > count0 + 2:        # clearly more contacts under the cover than as given
                x[6 * k:6 * k + 3] = shift
                gaps.append(g_k)
                weights.append(count)
                shifts.append(shift @ A[k] if mounted is not None else shift)
        if gaps and not fixed_gap:
            x[-1] = float(np.average(gaps, weights=weights))
        if gaps and mounted is not None:                 # the mount's start: the captures' shifts, in its frame
            x = lift @ np.r_[np.average(shifts, axis=0, weights=weights), np.zeros(3), x[-1]]
        if gaps:
            far = 2 * reach                              # the search put every capture within a cell or two
    if mounted is not None:
        y = np.linalg.lstsq(lift, x, rcond=None)[0]      # x lies in lift's range: exact
        H = prior_y.copy()
    for it in range(iterations):
        reach_now = reach + (far - reach) * max(0.0, 1.0 - it / max(1.0, iterations / 2))
        J, r, sigma, _, _, pairs = terms(x, reach_now)
        if not len(r):
            break
        if overlap_sigma is None and pairs.any():      # the pairs' spread as they stand now (correlated: PATCH)
            sigma[pairs] = max(PAIR_FLOOR, 1.4826 * float(np.median(np.abs(r[pairs])))) * math.sqrt(PATCH)
        w = _huber_weights(r / sigma, HUBER) / sigma ** 2
        if mounted is not None:                 # the same residuals, in the mount's unknowns
            J = J @ lift
            H = (J * w[:, None]).T @ J + prior_y
            b = (J * w[:, None]).T @ r + prior_y @ y
        else:
            H = (J * w[:, None]).T @ J + prior
            b = (J * w[:, None]).T @ r + prior @ x
        if fixed_gap:
            H[-1, :], H[:, -1], H[-1, -1], b[-1] = 0.0, 0.0, 1.0, 0.0
        step = np.linalg.solve(H, -b)
        if mounted is not None:
            y = y + step
            x = lift @ y
        else:
            x = x + step
        if reach_now == reach and np.abs(step[:-1]).max() < 1e-7:
            break
    _, _, _, counts, overlaps, _ = terms(x)
    out, mount_fix = [], None
    if mounted is not None:
        # the mount's correction about the camera there, within the bound; each capture's as the base saw it then
        t_m, w_m, over, u_m = _within_bound(y[0:3], y[3:6], pivot_m - camera_m, max_translation, max_rotation)
        mount_fix = CaptureCorrection(t_m, w_m, camera_m, sum(counts), sum(overlaps) // 2, over > 1.0,
                                      _weak(H[:6, :6], prior_y[:6, :6]), sum(len(s) for s in table))
        bounded = lift @ np.r_[u_m, w_m, y[-1]]
        out = [dataclasses.replace(mount_fix.through(mounted[k]), contacts=counts[k], overlap=overlaps[k], weak=(),
                                   support=len(table[k])) for k in range(K)]
    else:
        bounded = x.copy()                 # the (u, w) of the corrections as kept, for their misfit
        for k in range(K):
            t_k, w_k, over, u_k = _within_bound(x[6 * k:6 * k + 3], x[6 * k + 3:6 * k + 6], pivots[k] - origins[k],
                                                max_translation, max_rotation)
            bounded[6 * k:6 * k + 6] = np.r_[u_k, w_k]
            block = slice(6 * k, 6 * k + 6)
            out.append(CaptureCorrection(t_k, w_k, origins[k].copy(), counts[k], overlaps[k], over > 1.0,
                                         _weak(H[block, block], prior[block, block]), len(table[k])))
    after, g1 = contact_misfit(bounded)
    bound = (float(max_translation), float(max_rotation))
    held = plane is not None and all(len(t) >= MIN_SUPPORT for t in table)    # every capture sees the table
    if sum(c.contacts for c in out) < MIN_CONTACTS and not held:   # too few to say anything: the captures as given
        none = ("x", "y", "z", "rx", "ry", "rz")
        out = [CaptureCorrection(np.zeros(3), np.zeros(3), c.origin, c.contacts, c.overlap, False, none) for c in out]
        if mount_fix is not None:
            mount_fix = CaptureCorrection(np.zeros(3), np.zeros(3), camera_m, mount_fix.contacts, mount_fix.overlap,
                                          False, none)
        return CaptureCorrections(out, g0, before, before, bound, enough=False, mount=mount_fix)
    return CaptureCorrections(out, float(x[-1]) if fixed_gap else g1, before, after, bound, mount=mount_fix)


def _within_bound(u: np.ndarray, w: np.ndarray, lever: np.ndarray, max_translation: float, max_rotation: float):
    """A correction found about its pivot, ``(u, w)``, as the camera's: ``(t, w, over, u)`` with ``t`` the
    translation about the optical centre (``lever`` = pivot - centre: ``t = u + (I - R(w)) lever``), both scaled back
    onto the bound where the solution went beyond it (``over`` > 1: by how much), and ``u`` of what is kept."""
    w = np.array(w, dtype=np.float64)
    t = u + (np.eye(3) - rotation_matrix(w)) @ lever
    over = max(np.linalg.norm(t) / max_translation, np.linalg.norm(w) / max_rotation)
    if over > 1.0:
        t, w = t / over, w / over
    return t, w, float(over), t - (np.eye(3) - rotation_matrix(w)) @ lever


def _weak(H: np.ndarray, prior: np.ndarray) -> tuple:
    """What the data left to the prior: the directions of a correction's `(6, 6)` curvature ``H`` (the prior's
    included) along which the data's part is below :data:`WEAK` of the prior's, named by their largest axis."""
    vals, vecs = np.linalg.eigh(np.linalg.solve(prior, H - prior))
    return tuple(sorted({("x", "y", "z", "rx", "ry", "rz")[int(np.argmax(np.abs(v)))]
                         for lam, v in zip(vals, vecs.T) if lam < WEAK}))


def _mount_poses(mount, K: int) -> np.ndarray | None:
    """``mount`` as `(K, 4, 4)` rigid poses, checked; None without one."""
    if mount is None:
        return None
    M = np.asarray(mount, dtype=np.float64)
    if M.shape != (K, 4, 4) or not np.isfinite(M).all():
        raise ValueError(f"correct_captures: mount must be ({K}, 4, 4) finite poses, one per capture, got shape "
                         f"{M.shape}")
    R = M[:, :3, :3]
    if not (np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-6) and np.allclose(np.linalg.det(R), 1.0)
            and np.allclose(M[:, 3], [0.0, 0.0, 0.0, 1.0])):
        raise ValueError("correct_captures: mount: every pose must be a rigid transform (a rotation and a translation)")
    return M
