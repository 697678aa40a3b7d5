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
    exists; it keeps the merged iterations in the checkpoint, and the same render with the same
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
    _wait_for_idle_cpus()
    resumed = cluster_render(scene, ON_CLUSTER, checkpoint=path)
    assert resumed.stats["cluster_resumed_iterations"] == len(done)
    assert_same_render(resumed, reference)
    with pytest.raises(CheckpointMismatch, match="another scene or other settings"):
        cluster_render(scene, ON_CLUSTER.replace(seed=8), checkpoint=path)


def test_time_limit_merges_the_completed_iterations(cluster, scene):
    """iterations = 0 with a time limit: iterations are submitted until the limit, then the
    running ones are cancelled; the image averages those that completed."""
    t0 = time.perf_counter()
    result = cluster_render(scene, ON_CLUSTER.replace(iterations=0, time_limit=3.0))
    assert time.perf_counter() - t0 < 3.0 + 10.0
    assert result.stats["iterations"] >= 1 and result.stopped_by == "time_limit"
    assert np.isfinite(result.image).all() and result.image[..., :3].mean() > 0
    _wait_for_idle_cpus()


def test_path_frames_are_one_task(cluster, scene):
    s = RenderSettings(integrator="PATH", samples=2, seed=3)
    assert_same_render(cluster_render(scene, s.replace(cluster="auto")), render(scene, s))
