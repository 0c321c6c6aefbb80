"""Data in and out: the ``.gpioius`` dataset/log format, checkpoints, importers of point clouds, contact tables and
ROS 2 bags, offline fitting and replay, runs step by step, and exports of the estimated surfaces."""

from . import checkpoints, datasets, export, importers, offline, outputs, rosbag, runs
from .export import export_run
from .importers import FilePointCloud
from .rosbag import BagImportError, import_bag
from .runs import RunHistory, load_run
from .checkpoints import CheckpointError, load_checkpoint, save_checkpoint
from .datasets import Dataset, DatasetError, LogWriter, TornLogWarning, load_dataset, read_records, replay, save_dataset

__all__ = ["FilePointCloud", "checkpoints", "datasets", "export", "importers", "offline", "outputs", "rosbag", "runs",
           "export_run", "import_bag", "BagImportError", "RunHistory", "load_run", "CheckpointError", "load_checkpoint",
           "save_checkpoint", "Dataset", "DatasetError", "LogWriter", "TornLogWarning", "load_dataset", "read_records",
           "replay", "save_dataset"]
