"""Data in and out: the ``.gpioius`` dataset/log format, checkpoints, importers of point clouds and contact
tables, offline fitting and replay."""

from . import checkpoints, datasets, importers, offline
from .checkpoints import CheckpointError, load_checkpoint, save_checkpoint
from .datasets import Dataset, DatasetError, LogWriter, TornLogWarning, load_dataset, read_records, replay, save_dataset

__all__ = ["checkpoints", "datasets", "importers", "offline", "CheckpointError", "load_checkpoint",
           "save_checkpoint", "Dataset", "DatasetError", "LogWriter", "TornLogWarning", "load_dataset",
           "read_records", "replay", "save_dataset"]
