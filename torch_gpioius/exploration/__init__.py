"""Active visuo-tactile exploration: public types, the contracts of its parts, and one loop for every world.

* types: :class:`Observations` (a batch), :class:`ExplorationState`, :class:`StepRecord`, :class:`ExploreConfig`,
  :class:`Run`, :class:`Trace`;
* contracts (:mod:`~torch_gpioius.exploration.protocols`): :class:`Toucher`, :class:`TouchModel`,
  :class:`EvidencePolicy`, :class:`Recorder`; stop rules (:class:`StopRule`); worlds (:class:`World`,
  :class:`Hardware`); the registries of worlds, touch models and evidence policies (:func:`register_world`,
  :func:`register_touch_model`, :func:`register_evidence_policy`; :mod:`torch_gpioius.core.registry`);
* the loop: :func:`run` (``torch_gpioius.explore``, the one public explore, builds its settings and adds the
  crash-safe log and resume).
"""

from ..core.moved import renamed
from .config import MODES, ExploreConfig, Run
from .evidence import Evidence, TapPolicy
from . import loop
from .loop import begin, run
from .observations import (Observations, ObservationPolicy, free_space_along, retract_free_space, thin_points,
                           vision_observations)
from .patches import PatchThinning, patch_observations
from .policies import EVIDENCE_POLICIES, evidence_policy, register_evidence_policy
from .protocols import EvidencePolicy, Recorder, Toucher, TouchModel, TouchModelBase
from .reach import ReachPlan, ReachPolicy
from .recorders import IntervalRecorder, MetricsRecorder, NoEstimateWarning, ProgressRecorder
from .recovery import NoProgress
from .registry import WORLDS, SceneSupport, WorldEntry, make_world, register_world, world_entry, world_names
from .state import RECORD_FIELDS, ExplorationState, StepRecord
from .stopping import OnceAround, StopRule, TravelBudget, gone_around, largest_uncovered_gap
from .touch import TOUCH_MODELS, PointTouch, register_touch_model, touch_model
from .trace import Trace
from .world import ExplorationDefaults, Hardware, Measurement, RobotWorld, World, geometry_hash

__all__ = ["run", "begin", "MODES", "ExploreConfig", "Run", "Observations", "ObservationPolicy",
           "ExplorationState", "StepRecord", "RECORD_FIELDS", "Trace", "Toucher", "TouchModel", "TouchModelBase",
           "EvidencePolicy", "Recorder", "MetricsRecorder", "NoEstimateWarning", "IntervalRecorder", "ProgressRecorder",
           "Evidence", "TapPolicy", "ReachPolicy", "ReachPlan", "NoProgress", "EVIDENCE_POLICIES", "evidence_policy",
           "register_evidence_policy", "register_touch_model", "WORLDS", "SceneSupport",
           "PointTouch", "TOUCH_MODELS", "touch_model", "StopRule", "OnceAround", "TravelBudget", "gone_around",
           "largest_uncovered_gap", "World", "Hardware", "ExplorationDefaults", "Measurement", "RobotWorld",
           "geometry_hash", "register_world", "world_entry", "world_names", "make_world", "WorldEntry",
           "free_space_along", "retract_free_space", "thin_points", "vision_observations", "PatchThinning",
           "patch_observations"]


#: The names of earlier releases (one explore: torch_gpioius.explore; "settings" are the estimator's).
__getattr__ = renamed(__name__, {"explore": ("torch_gpioius", "explore", loop.EXPLORE_MOVED),
                                 "PatchSettings": ("torch_gpioius.exploration.patches", "PatchThinning",
                                                   "settings are the estimator's")})
