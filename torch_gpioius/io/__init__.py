"""Data in and out: the ``.gpioius`` dataset/log format, checkpoints, importers of point clouds, contact tables and
ROS 2 bags, runs step by step, exports of the estimated surfaces, and the output folders' rules (atomic writes,
claims, locks). Fitting and replaying recorded data is :mod:`torch_gpioius.fitting`."""

from . import checkpoints, datasets, export, importers, outputs, rosbag, runs
from .export import export_run
from .importers import FilePointCloud
from .rosbag import BagImportError, import_bag
from .runs import RunHistory, load_run
from .checkpoints import CheckpointError, load_checkpoint, save_checkpoint
from .datasets import Dataset, DatasetError, LogWriter, TornLogWarning, load_dataset, read_records, replay, save_dataset

__all__ = ["FilePointCloud", "checkpoints", "datasets", "export", "importers", "outputs", "rosbag", "runs",
           "export_run", "import_bag", "BagImportError", "RunHistory", "load_run", "CheckpointError", "load_checkpoint",
           "save_checkpoint", "Dataset", "DatasetError", "LogWriter", "TornLogWarning", "load_dataset", "read_records",
           "replay", "save_dataset"]


def __getattr__(name):
    if name == "offline":               # torch_gpioius.fitting now (core.moved warns)
        import importlib

        return importlib.import_module(f"{__name__}.offline")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
