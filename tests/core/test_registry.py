"""The one way to register an extension by name (torch_gpioius.core.registry): names, aliases in any case where asked,
conflicts refused by name, capabilities declared and filtered on, built-in modules imported on first use, and
plugins that reach the command line through GPIOIUS_PLUGINS."""

from dataclasses import dataclass

import pytest

from torch_gpioius.core.registry import Entry, Registry


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
    from torch_gpioius.core import registry
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


SHADOW = '''
from torch_gpioius.kernels import Matern52, register_kernel


@register_kernel
class Shadow(Matern52):
    """Twice the Matern: registered under the built-in's own name."""
    kind = "Matern52"

    def value(self, x1, x2):
        return 2 * super().value(x1, x2)
'''

NOT_PD = '''
import torch
from torch_gpioius.kernels import Matern52, register_kernel


@register_kernel
class Bowl(Matern52):
    """k = 1 - r^2 / l^2: a valid shape at r = 0, not positive definite."""
    kind = "Bowl"

    def value(self, x1, x2):
        return 1.0 - torch.cdist(x1, x2).square() / self.length ** 2
'''


@pytest.mark.parametrize("source, match", [
    (SHADOW, r"'Matern52' is already the kernel torch_gpioius.kernels.matern.Matern52"),
    (NOT_PD, r"kernel Bowl: not positive definite: the Gram matrix of 40 points has the eigenvalue -"),
    ("import sys\nsys.exit(3)\n", r"called sys.exit\(3\) while being imported"),
])
def test_a_plugin_that_would_replace_a_builtin_break_every_run_or_exit_is_refused_by_name(
        source, match, tmp_path, monkeypatch, capsys):
    """Issue 60, items 4, 14 and 15: a plugin's kernel of kind "Matern52" silently replaced the built-in (its alias
    gone, K_t doubled, existing files read with it); a kernel that is not positive definite was accepted and every
    run of a study then failed; a plugin calling sys.exit(3) ended gpioius with status 3 and no word. Each is now
    refused when the plugin is imported, with the plugin and the reason named, and the built-in stays."""
    from torch_gpioius.core import registry
    from torch_gpioius.cli import main
    from torch_gpioius.kernels import KERNELS, Matern52, kernel_named

    name = f"bad_plugin_{abs(hash(source)) % 10**8}"
    (tmp_path / f"{name}.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("GPIOIUS_PLUGINS", name)
    monkeypatch.setattr(registry, "_LOADED", set())
    assert main(["registered", "kernels"]) == 2
    err = capsys.readouterr().err
    assert f"plugin '{name}' (GPIOIUS_PLUGINS)" in err and __import__("re").search(match, err), err
    assert KERNELS["matern52"] is Matern52 and type(kernel_named("Matern52", 0.1)) is Matern52
    assert "Bowl" not in KERNELS


def test_a_kernel_class_reloaded_is_registered_again_and_one_needing_arguments_is_checked_when_first_built():
    import torch

    from torch_gpioius.kernels import KERNELS, Matern52, from_description, register_kernel

    def define(kind):
        class Scaled(Matern52):
            def __init__(self, factor, lengthscale=0.1):
                super().__init__(lengthscale)
                self.factor = factor

            def value(self, x1, x2):
                return self.factor * super().value(x1, x2)

            def prior_variance(self, scale=1.0):
                return self.factor * super().prior_variance(scale)

            def describe(self):
                return {"kernel": self.kind, "factor": self.factor, "lengthscale": self.length}
        Scaled.kind = kind
        return Scaled

    first, again = define("ScaledForTest"), define("ScaledForTest")     # one definition twice (a module reloaded)
    register_kernel(first)
    register_kernel(again)
    assert KERNELS["ScaledForTest"] is again
    built = from_description({"kernel": "ScaledForTest", "factor": 2.0, "lengthscale": 0.1})
    origin = torch.zeros(1, 3, dtype=torch.float64)
    assert float(built.value(origin, origin)) == 2.0
    register_kernel(define("NegativeForTest"))           # needs its factor: checked on its first instance by name
    with pytest.raises(ValueError, match="values must be finite and the prior variance positive"):
        from_description({"kernel": "NegativeForTest", "factor": -1.0, "lengthscale": 0.1})
