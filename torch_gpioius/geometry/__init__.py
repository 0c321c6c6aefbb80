"""Points, curves and the estimated surface, apart from any model's arithmetic: voxel averaging (:mod:`.voxels`),
polylines (:mod:`.polylines`), the estimated surface's differential geometry by autograd, eq. (20)-(22)
(:mod:`.differential`), its extraction as curves and meshes on the level set (:mod:`.surfaces`) and its comparison
with a true shape (:mod:`.metrics`). A model enters only through its ``predict``; this layer imports only
:mod:`torch_gpioius.core`."""

from .differential import SurfaceGeometry, predict_mean_task, predict_task, surface_geometry

__all__ = ["SurfaceGeometry", "surface_geometry", "predict_task", "predict_mean_task"]
