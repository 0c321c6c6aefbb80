"""The cover's gap under each contact recomputed by hand, for the tests of ``CoverGap`` and of the scripts that
replay it: an independent reference (every distance sorted, the plane's normal from an eigendecomposition)."""

import numpy as np


def gaps_by_hand(contacts, seen, reach, neighbours=6) -> np.ndarray:
    """`(j,)` each counted contact's gap [m]: the ``neighbours`` nearest seen points by sorting every distance, the
    plane through them with the least eigenvector of their scatter as its normal, the contact's distance from it;
    a contact counts where its foot lies within ``reach`` [m] of the patch's mean."""
    counted = []
    for c in np.asarray(contacts, dtype=float):
        patch = seen[np.argsort(np.linalg.norm(seen - c, axis=1))[:neighbours]]
        centre = patch.mean(axis=0)
        normal = np.linalg.eigh((patch - centre).T @ (patch - centre))[1][:, 0]
        gap = abs(float((c - centre) @ normal))
        if np.sqrt(max(float((c - centre) @ (c - centre)) - gap ** 2, 0.0)) <= reach:
            counted.append(gap)
    return np.array(counted)
