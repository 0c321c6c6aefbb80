"""The one way to register an extension by name (torch_gpioius.registry): names, aliases in any case where asked,
conflicts refused by name, capabilities declared and filtered on, built-in modules imported on first use, and
plugins that reach the command line through GPIOIUS_PLUGINS."""

from dataclasses import dataclass

import pytest

from torch_gpioius.registry import Entry, Registry


@dataclass
class ToolEntry(Entry):
    sharp: bool = False


def test_names_aliases_and_capabilities():
    reg = Registry("tool", entry_type=ToolEntry, case_sensitive=False)
    reg.register("Knife", int, aliases=("blade",), sharp=True, description="cuts")
    reg.register("Spoon", float)
    assert reg.names() == ["Knife", "Spoon"] and reg.choices() == ["Knife", "blade", "Spoon"]
    assert reg["BLADE"] is int and reg.resolve("knife") == "Knife" and "spoon" in reg and "fork" not in reg
    assert reg.names(sharp=True) == ["Knife"] and len(reg) == 2 and list(reg) == ["Knife", "Spoon"]
    assert "| `Knife` | `blade` | cuts |" in reg.markdown()
    with pytest.raises(ValueError, match=r"tool: unknown 'fork'; choose among \['Knife', 'blade', 'Spoon'\]"):
        reg.resolve("fork")
    with pytest.raises(KeyError):
        reg["fork"]


def test_conflicts_and_unknown_capabilities_are_refused_by_name():
    reg = Registry("tool", entry_type=ToolEntry, old_names={"shiv": "Knife"})
    reg.register("Knife", int)
    reg.register("Knife", int)                                   # the same object again: nothing changes
    with pytest.raises(ValueError, match="'Knife' is already int"):
        reg.register("Knife", float)
    with pytest.raises(ValueError, match="'shiv' is an old name of 'Knife'"):
        reg.register("shiv", float)
    with pytest.raises(ValueError, match=r"unknown capabilities \['colour'\]; a tool has \['description', 'sharp'\]"):
        reg.register("Fork", float, colour="red")
    with pytest.raises(ValueError, match="must be an identifier"):
        reg.register("a fork", float)
    with pytest.warns(DeprecationWarning, match="tool 'shiv' is called 'Knife' now"):
        assert reg.resolve("shiv", warn=True) == "Knife"


def test_a_builtin_entry_is_imported_on_first_use(tmp_path, monkeypatch):
    (tmp_path / "late_tools.py").write_text(f"import sys\nsys.modules[{__name__!r}].LATE.register('saw', bytes)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert LATE.names() == ["saw"] and "saw" not in LATE._entries     # listed before its module is imported
    assert LATE["saw"] is bytes


LATE = Registry("tool", builtin={"saw": "late_tools"})


PLUGIN = '''
from torch_gpioius.kernels import InverseMultiquadricKernel, register_kernel


@register_kernel(aliases=("plugin_imq",), description="a plugin's kernel")
class PluginIMQ(InverseMultiquadricKernel):
    kind = "PluginIMQ"
'''


def test_a_plugin_named_in_the_environment_reaches_the_command_line(tmp_path, monkeypatch, capsys):
    """Issue 53: a registration reached the command line only from Python. GPIOIUS_PLUGINS (or an entry point of
    torch_gpioius.plugins) names the module that registers; `gpioius registered` and `--kernel` then know it."""
    from torch_gpioius import registry
    from torch_gpioius.cli import main

    (tmp_path / "my_lab_plugin.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("GPIOIUS_PLUGINS", "my_lab_plugin")
    monkeypatch.setattr(registry, "_LOADED", set())
    assert main(["registered", "kernels"]) == 0
    out = capsys.readouterr().out
    assert "| `PluginIMQ` | `plugin_imq` | `PluginIMQ` | a plugin's kernel |" in out
    from torch_gpioius.kernels import KERNELS, kernel_named

    assert type(kernel_named("plugin_imq", 0.2)).__name__ == "PluginIMQ" and "PluginIMQ" in KERNELS
    monkeypatch.setenv("GPIOIUS_PLUGINS", "my_lab_plugin, no_such_plugin")
    assert main(["registered"]) == 2
    err = capsys.readouterr().err
    assert "plugin 'no_such_plugin' (GPIOIUS_PLUGINS) cannot be imported: ModuleNotFoundError" in err
