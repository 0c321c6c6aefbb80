"""Active visuo-tactile exploration: one loop (:func:`explore`) for every world, behind the robot, force-sensor
and point-cloud interfaces of :mod:`torch_gpioius.exploration.world`."""

from .evidence import TapPolicy
from .loop import EVIDENCE, MODES, explore
from .observations import ObservationPolicy, free_space_along, retract_free_space, thin_points, vision_observations
from .stopping import OnceAround, StopRule, TravelBudget, gone_around, largest_uncovered_gap
from .trace import Trace
from .world import ExplorationDefaults, Hardware, Measurement, RobotWorld, World

__all__ = ["explore", "MODES", "EVIDENCE", "TapPolicy", "ObservationPolicy", "free_space_along", "retract_free_space",
           "thin_points", "vision_observations", "OnceAround", "StopRule", "TravelBudget", "gone_around",
           "largest_uncovered_gap", "Trace", "ExplorationDefaults", "Hardware", "Measurement", "RobotWorld", "World"]
