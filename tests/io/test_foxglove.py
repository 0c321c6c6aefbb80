"""MCAP export with Foxglove schemas, read back with the mcap library and the schemas stored in the file."""

import json

import numpy as np
import pytest

pytest.importorskip("foxglove")
mcap_reader = pytest.importorskip("mcap.reader")

import torch_gpioius as tg  # noqa: E402
from torch_gpioius.cli import main  # noqa: E402
from torch_gpioius.io.foxglove import INSIDE_TOPIC, MCAP_TOPICS, PAD_TOPIC, export_mcap  # noqa: E402
from torch_gpioius.io.runs import load_run  # noqa: E402
from torch_gpioius.models.overrides import EstimatorOverrides  # noqa: E402


def _decoder(schema):
    """A protobuf message class from the FileDescriptorSet stored in an MCAP schema record."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def _exported(log, tmp_path, topics):
    """Export ``log`` to MCAP and read it back: the run, the file's topics, and the last message of each of
    ``topics`` as ``(schema, message)``."""
    out = tmp_path / (log.stem + ".mcap")
    export_mcap(log, out)
    with open(out, "rb") as f:
        reader = mcap_reader.make_reader(f)
        found = {c.topic for c in reader.get_summary().channels.values()}
        last = {c.topic: (s, m) for s, c, m in reader.iter_messages(topics=list(topics))}
    return load_run(log), found, last


@pytest.fixture(scope="module")
def log_2d(tmp_path_factory):
    path = tmp_path_factory.mktemp("runs") / "A.gpioius"
    tg.explore(tg.sim.paper_objects_2d()["A"], mode="visual-tactile", max_steps=6, log=path, progress=False)
    return path


def test_topics_schemas_and_contents(log_2d, tmp_path):
    out = tmp_path / "run.mcap"
    info = export_mcap(log_2d, out, every=2)
    run = load_run(log_2d)
    assert info["steps"] == 4                                   # steps 0, 2, 4, 6
    with open(out, "rb") as f:
        reader = mcap_reader.make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == set(MCAP_TOPICS)
        counts = summary.statistics.channel_message_counts
        assert counts[topics["/gpioius/cloud"].id] == 1 and counts[topics["/gpioius/contacts"].id] == 4
        assert summary.schemas[topics["/gpioius/estimate"].schema_id].name == "foxglove.SceneUpdate"
        last = {}
        for schema, channel, message in reader.iter_messages():
            last[channel.topic] = (schema, message)
    schema, message = last["/gpioius/contacts"]
    pc = _decoder(schema).FromString(message.data)
    pts = np.frombuffer(pc.data, dtype=np.float32).reshape(-1, 3)
    ds = run.states[6]
    truth = ds.x[(ds.task == 0) & (ds.y == 0)]
    np.testing.assert_allclose(pts[:, :2], truth, atol=1e-6)      # float32 of positions below 1 m
    assert np.all(pts[:, 2] == 0) and pc.frame_id == "scene"
    schema, message = last["/gpioius/estimate"]
    update = _decoder(schema).FromString(message.data)
    assert update.entities[0].id == "estimate" and len(update.entities[0].lines[0].points) > 20
    metrics = json.loads(last["/gpioius/metrics"][1].data)
    assert metrics["step"] == 6 and metrics["similarity"] == pytest.approx(run.params[6]["similarity"], rel=1e-12)


def test_cli_and_refusals(log_2d, tmp_path, capsys):
    out = tmp_path / "a.mcap"
    assert main(["export", str(log_2d), "--mcap", str(out)]) == 0
    assert "Foxglove schemas" in capsys.readouterr().out and out.stat().st_size > 0
    for argv, expected in ((["export", str(log_2d), "--mcap", str(out)], "exists"),
                           (["export", str(log_2d), "--mcap", str(tmp_path / "b.bag")], "must end in .mcap"),
                           (["export", str(log_2d), "--mcap", str(tmp_path / "c.mcap"), "--step", "3"],
                            "does not combine")):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert expected in err and "\n" not in err


def test_a_patch_run_exports_its_pads(tmp_path):
    from torch_gpioius.exploration.registry import make_world

    log = tmp_path / "patch.gpioius"
    tg.explore(make_world("forcefield", "E", 0, smoke=True), "tactile", touch="patch", max_travel=0.02,
               metrics_every=100, log=log, progress=False)
    run, topics, last = _exported(log, tmp_path, [PAD_TOPIC])
    assert topics == set(MCAP_TOPICS) | {PAD_TOPIC}
    schema, message = last[PAD_TOPIC]
    update = _decoder(schema).FromString(message.data)
    loop = np.array([[p.x, p.y, p.z] for p in update.entities[0].lines[0].points])
    np.testing.assert_allclose(loop, run.pad_footprints(run.steps[-1])[-1], atol=1e-12)


def test_a_run_with_inside_points_exports_them_on_their_own_topic(tmp_path):
    """Points known to lie inside (labels below 0, behind the touches and the seen surface) get their own topic at
    each step; the camera's cloud keeps its surface and free space only."""
    import dataclasses

    from torch_gpioius.sim import sphere_scene

    scene = sphere_scene(subdivisions=3)
    policy = dataclasses.replace(scene.defaults.policy, touch_inside=0.02, vision_inside=0.01)
    log = tmp_path / "inside.gpioius"
    tg.explore(scene, max_travel=0.03, metrics_every=100, settings=EstimatorOverrides(policy=policy), log=log,
               progress=False)
    run, topics, got = _exported(log, tmp_path, [INSIDE_TOPIC, "/gpioius/cloud"])
    assert topics == set(MCAP_TOPICS) | {INSIDE_TOPIC}
    ds, first = run.states[run.steps[-1]], run.states[run.steps[0]]
    seen = first.x[(first.task == 1) & (first.y >= 0)]
    for topic, want in ((INSIDE_TOPIC, ds.x[ds.y < 0]), ("/gpioius/cloud", seen)):
        schema, message = got[topic]
        pts = np.frombuffer(_decoder(schema).FromString(message.data).data, dtype=np.float32).reshape(-1, 3)
        assert len(want) > 0
        np.testing.assert_allclose(pts, want, atol=1e-6)
    assert bool((ds.y[ds.task == 0] < 0).any()) and bool((ds.y[ds.task == 1] < 0).any())    # both kinds exported
