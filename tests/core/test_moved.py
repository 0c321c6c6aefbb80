"""The modules and names of earlier releases: each old path gives the object that lives at its new one, says so once
with a DeprecationWarning pointed at the importing line, and leaves the new module as it was (its name, its spec)."""

import importlib
import pickle
import sys
import warnings

import pytest

from torch_gpioius.core.moved import MODULES, MovedModules, renamed


@pytest.mark.parametrize("old", sorted(MODULES))
def test_every_moved_module_imports_from_its_old_path_with_a_warning_naming_the_new(old):
    new, _ = MODULES[old]
    module = importlib.import_module(new)
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=f"{old} is {new} now") as caught:
        __import__(old)                                                 # as an import statement does
    aliased = sys.modules[old]
    assert aliased is module
    assert module.__name__ == new and module.__spec__.name == new       # the new module keeps its own identity
    assert caught[0].filename == __file__                               # pointed at the import, not importlib's frames
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert importlib.import_module(old) is module                   # once: later imports are quiet


def test_an_old_path_in_a_from_import_and_a_pickle_still_loads():
    """A checkpoint pickled before the move names the old module; it loads to the class that lives at the new one."""
    from torch_gpioius.exploration.contact import ContactConfig

    sys.modules.pop("torch_gpioius.contact", None)
    new_bytes = pickle.dumps(ContactConfig(), protocol=0)          # text: the module path can be swapped in place
    old_bytes = new_bytes.replace(b"torch_gpioius.exploration.contact", b"torch_gpioius.contact")
    assert b"torch_gpioius.contact" in old_bytes
    with pytest.warns(DeprecationWarning, match="torch_gpioius.contact is torch_gpioius.exploration.contact now"):
        loaded = pickle.loads(old_bytes)
    assert type(loaded) is ContactConfig and loaded == ContactConfig()
    sys.modules.pop("torch_gpioius.metrics", None)
    with pytest.warns(DeprecationWarning, match="torch_gpioius.metrics is"):
        from torch_gpioius.metrics import hausdorff_distance
    from torch_gpioius.geometry.metrics import hausdorff_distance as new
    assert hausdorff_distance is new


def test_the_finder_answers_only_the_moved_names_and_is_installed_once():
    import torch_gpioius  # noqa: F401

    finders = [f for f in sys.meta_path if isinstance(f, MovedModules)]
    assert len(finders) == 1
    assert finders[0].find_spec("torch_gpioius.kernels") is None and finders[0].find_spec("numpy") is None
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("torch_gpioius.no_such_module")


def test_a_renamed_name_gives_the_new_object_with_a_warning_and_others_an_attribute_error():
    getattr_ = renamed("pkg.mod", {"Old": ("torch_gpioius.core.exact", "exact_arithmetic", "renamed")})
    from torch_gpioius.core.exact import exact_arithmetic

    with pytest.warns(DeprecationWarning, match=r"pkg\.mod\.Old is torch_gpioius\.core\.exact\.exact_arithmetic now"):
        assert getattr_("Old") is exact_arithmetic
    with pytest.raises(AttributeError, match="'pkg.mod' has no attribute 'New'"):
        getattr_("New")


def test_the_simulated_cameras_old_names_in_pointcloud_forward_to_the_simulated_sensors():
    import torch_gpioius.sensors.pointcloud as pointcloud
    from torch_gpioius.sensors.simulated import CameraError, SimulatedDepthCamera

    for name, new in (("CameraError", CameraError), ("SimulatedDepthCamera", SimulatedDepthCamera)):
        with pytest.warns(DeprecationWarning, match=f"pointcloud.{name} is torch_gpioius.sensors.simulated.camera"):
            assert getattr(pointcloud, name) is new
