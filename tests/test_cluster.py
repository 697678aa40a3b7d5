"""Scale-out on Ray (:mod:`ercuts_core.cluster`, issue 16), with real Ray: a local cluster of a
head and one more node (separate raylets and worker processes, one CPU each) started once for
the module. A frame's iterations are tasks; the merged image must be bit-identical to
``render()`` of the same iterations, also when a worker process is killed during a task, after
a cancel and after a resume from a checkpoint."""
from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest
import ray
from ray.cluster_utils import Cluster

from ercuts_core import RenderSettings, render
from ercuts_core.checkpoint import CheckpointMismatch, load_checkpoint
from ercuts_core.cluster import ClusterError, Driver, FrameJob, connect, frame_job, npz_bytes
from ercuts_core.cluster import render as cluster_render
from ercuts_core.render import render_film
from ercuts_core.scenes import cornell_box

FAST = dict(integrator="ERCUTS", samples=4, chain_length=20, chains_per_pixel=0.5, direct_samples=8)
SETTINGS = RenderSettings(**FAST, seed=7, iterations=6)
ON_CLUSTER = SETTINGS.replace(cluster="auto")


def ray_processes() -> list[tuple[int, str]]:
    """(pid, command line) of this machine's Ray processes: raylets, GCS servers, workers."""
    out = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                cmd = fh.read().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        if cmd.startswith("ray::") or any(k in cmd for k in ("/ray/core/src/ray/raylet", "gcs_server",
                                                              "ray/_private/workers/default_worker")):
            out.append((int(pid), cmd))
    return out


@pytest.fixture(scope="module")
def cluster():
    """A head and a second node with one CPU each, this process connected as the driver;
    afterwards no Ray process may be left."""
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    try:
        c.add_node(num_cpus=1)
        with connect(c.address):
            c.wait_for_nodes()
            yield c
    finally:
        c.shutdown()
    deadline = time.monotonic() + 20
    while ray_processes() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not ray_processes(), ray_processes()


@pytest.fixture(scope="module")
def scene():
    return cornell_box(16, 12)


@pytest.fixture(scope="module")
def reference(scene):
    """The single-process render of the same six iterations."""
    return render(scene, SETTINGS)


def assert_same_render(a, b):
    np.testing.assert_array_equal(a.image, b.image)
    assert set(a.aovs) == set(b.aovs)
    for name in a.aovs:
        np.testing.assert_array_equal(a.aovs[name], b.aovs[name], err_msg=name)


def test_merged_image_is_the_single_process_image(cluster, scene, reference):
    """Bit for bit: every task returns its iteration's float64 film, the driver folds them in
    iteration order as render() does; the tasks ran on both nodes' workers."""
    assert ray.cluster_resources()["CPU"] == 2 and len(ray.nodes()) == 2
    seen, previews = [], []
    result = cluster_render(scene, ON_CLUSTER, progress=lambda f, m: seen.append((f, m)),
                            preview=previews.append, scene="cornell", frame=3)
    assert_same_render(result, reference)
    assert result.stats["iterations"] == 6 and result.stopped_by is None and not result.cancelled
    assert result.stats["cluster_workers"] == 2
    assert result.stats["cluster_scene_bytes"] > 0 and result.stats["cluster_result_bytes"] > 16 * 12 * 8
    assert seen[-1][0] == pytest.approx(1.0) and "cornell" in seen[-1][1] and "frame 3" in seen[-1][1]
    assert np.all(np.diff([f for f, _ in seen]) >= 0)
    assert previews and previews[0].shape == (12, 16, 4)


def test_a_killed_worker_is_retried_with_the_same_seed(cluster, scene, reference):
    """SIGKILL the worker process of a running task: Ray re-runs the task (max_retries) with the
    same arguments, and the image is unchanged."""
    killed, stop = [], threading.Event()

    def killer():
        while not stop.is_set() and len(killed) < 2:
            for pid, cmd in ray_processes():
                if cmd.startswith("ray::ercuts "):     # a running task (its name, cluster.py)
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                    time.sleep(1.0)
                    break
            time.sleep(0.01)

    thread = threading.Thread(target=killer)
    thread.start()
    try:
        result = cluster_render(scene, ON_CLUSTER)
    finally:
        stop.set()
        thread.join()
    assert killed, "no running task was found to kill"
    assert_same_render(result, reference)


def test_a_raising_task_names_scene_frame_and_iteration(cluster, scene):
    """A frame whose description fails on the workers (no camera: the workers validate it): the
    error says which scene, frame and iteration, with the worker's exception; no task keeps running."""
    from dataclasses import replace

    broken = replace(scene, camera=None)
    job = FrameJob(npz_bytes(broken), ON_CLUSTER, scene="attic", frame=12)
    with pytest.raises(ClusterError, match=r"scene 'attic' frame 12, iteration \d: SceneError: .*camera"):
        Driver(ray).run([job])
    _wait_for_idle_cpus()


def _wait_for_idle_cpus(timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while ray.available_resources().get("CPU", 0) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert ray.available_resources().get("CPU", 0) == 2, "tasks still running"


def test_cancel_stops_every_task_and_keeps_the_merged_iterations(cluster, scene):
    merged = []
    result = cluster_render(scene, ON_CLUSTER, progress=lambda f, m: not merged, preview=merged.append)
    assert result.stopped_by == "cancel" and result.cancelled
    assert 1 <= result.stats["iterations"] < 6
    assert np.isfinite(result.image).all() and result.image[..., :3].mean() > 0
    _wait_for_idle_cpus()


def test_interrupted_driver_resumes_from_its_checkpoint(cluster, scene, reference, tmp_path):
    """The driver is interrupted (KeyboardInterrupt in its progress callback) once a checkpoint
    exists; it keeps the merged iterations in the checkpoint (their float64 sums are those of a
    single-process render of as many iterations, bit for bit), and the same render with the same
    checkpoint renders only the rest: the image is the uninterrupted one, bit for bit."""
    path = str(tmp_path / "frame.ckpt.npz")

    def interrupt(f, m):
        if os.path.exists(path):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        cluster_render(scene, ON_CLUSTER, progress=interrupt, checkpoint=path)
    job = frame_job(scene, ON_CLUSTER)
    from ercuts_core.checkpoint import checkpoint_key

    film, done = load_checkpoint(path, checkpoint_key(job.npz, ON_CLUSTER))
    assert done == list(range(len(done))) and 1 <= len(done) < 6 and film.passes_done == len(done)
    single = render_film(scene, SETTINGS.replace(iterations=len(done)))[0]     # float64 sums too
    for name, value in vars(single).items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(getattr(film, name), value, err_msg=name)
    for name, value in single.aov_sum.items():
        np.testing.assert_array_equal(film.aov_sum[name], value, err_msg=name)
    _wait_for_idle_cpus()
    resumed = cluster_render(scene, ON_CLUSTER, checkpoint=path)
    assert resumed.stats["cluster_resumed_iterations"] == len(done)
    assert_same_render(resumed, reference)
    with pytest.raises(CheckpointMismatch, match="another scene or other settings"):
        cluster_render(scene, ON_CLUSTER.replace(seed=8), checkpoint=path)


def test_time_limit_merges_the_completed_iterations(cluster, scene):
    """iterations = 0 with a time limit: iterations are submitted until the limit, then the
    running ones are cancelled (without the limit this render would never end); the image
    averages those that completed."""
    result = cluster_render(scene, ON_CLUSTER.replace(iterations=0, time_limit=3.0))
    assert result.stats["iterations"] >= 1 and result.stopped_by == "time_limit"
    assert np.isfinite(result.image).all() and result.image[..., :3].mean() > 0
    _wait_for_idle_cpus()


def test_path_frames_are_one_task(cluster, scene):
    s = RenderSettings(integrator="PATH", samples=2, seed=3)
    assert_same_render(cluster_render(scene, s.replace(cluster="auto")), render(scene, s))


FRAMES_ARGS = ["blend_scenes/cornell_box.blend", "-s", "1", "-e", "3", "--resolution", "16", "12",
               "--iterations", "2", "--skip-existing"]
#: The same frame exported and rendered in one process (render()), for comparison.
SINGLE = """
import io, sys, numpy as np
sys.argv = ["render_frames.py", *sys.argv[1:]]
sys.path.insert(0, "blend_scenes")
import render_frames
from ercuts_core import load_npz, render
args = render_frames.parse(sys.argv[1:-1])
args.skip_existing = False
scene = render_frames.open_scene(args)
job = next(render_frames.export_frames(scene, [1], args, "cornell_box"))
np.save(sys.argv[-1], render(load_npz(io.BytesIO(job.npz)), job.settings.replace(cluster="")).image)
"""


@pytest.mark.slow
def test_frame_range_writes_blender_named_exrs(cluster, tmp_path):
    """render_frames.py (bpy module, the add-on's exporter) on the cluster: one EXR per frame at
    Blender's path (cornell_####.exr), written whole (no temporary or checkpoint file is left);
    an existing frame is kept with --skip-existing; a frame's EXR is the image render() gives for
    the same exported description (Blender's EXR writer keeps it linear, top row first)."""
    import subprocess
    import sys

    from ercuts_core.image_io import read_exr

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = tmp_path / "out"
    out.mkdir()
    (out / "cornell_0002.exr").write_bytes(b"an earlier frame")
    pattern = str(out / "cornell_####")
    env = {**os.environ, "PYTHONPATH": root}
    run = subprocess.run([sys.executable, "blend_scenes/render_frames.py", *FRAMES_ARGS, "-o", pattern,
                          "--cluster", cluster.address, "--checkpoint"],
                         cwd=root, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-3000:]
    assert sorted(p.name for p in out.iterdir()) == [f"cornell_000{f}.exr" for f in (1, 2, 3)]
    assert (out / "cornell_0002.exr").read_bytes() == b"an earlier frame"
    assert "frame 2: " in run.stdout and "skipped" in run.stdout
    first, third = (read_exr(out / f"cornell_000{f}.exr")["RGBA"] for f in (1, 3))
    assert first.shape == (12, 16, 4) and first[..., :3].mean() > 0
    np.testing.assert_array_equal(first, third)          # a still scene, the same seed
    single = subprocess.run([sys.executable, "-c", SINGLE, *FRAMES_ARGS, "-o", pattern,
                             str(tmp_path / "single.npy")],
                            cwd=root, env=env, capture_output=True, text=True, timeout=300)
    assert single.returncode == 0, single.stderr[-3000:]
    np.testing.assert_array_equal(first, np.load(tmp_path / "single.npy"))


@pytest.mark.slow
def test_command_line_cluster_local_writes_the_same_file(tmp_path):
    """The issue's command, with and without ``--cluster local`` (a cluster started for the call
    and stopped after it): the same EXR, byte for byte."""
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": root}
    base = [sys.executable, "-m", "ercuts_core", "render", "builtin:cornell_box", "--iterations", "4",
            "--seed", "7", "--width", "16", "--height", "12"]
    for name, extra in (("plain", []), ("cluster", ["--cluster", "local"])):
        run = subprocess.run([*base, "-o", str(tmp_path / f"{name}.exr"), *extra], cwd=root, env=env,
                             capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr[-3000:]
    assert (tmp_path / "plain.exr").read_bytes() == (tmp_path / "cluster.exr").read_bytes()
    bad = subprocess.run([*base, "-o", str(tmp_path / "x.exr"), "--cluster", "nowhere"], cwd=root, env=env,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "is not 'local', 'auto'" in bad.stderr
