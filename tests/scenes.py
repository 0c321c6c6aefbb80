"""Scene files the tests write: a 6 cm ball on the table under a tight cover (a body whose truth is a sphere)."""

SCENE = """
name = "{name}"
[object]
mesh = "ball.stl"
at = [0.5, 0.0, 0.15]
[cover]
kind = "tight"
gap = 0.008
{extra}"""


def ball_scene(folder, name: str = "ball", extra: str = ""):
    """Write ``ball.stl`` (an icosphere of radius 6 cm) and ``<name>.toml`` (``extra``: more TOML) into ``folder``;
    returns the scene file's path."""
    import trimesh

    trimesh.creation.icosphere(3, 0.06).export(folder / "ball.stl")
    path = folder / f"{name}.toml"
    path.write_text(SCENE.format(name=name, extra=extra))
    return path
