"""Scale-out on Ray: one frame's ERCUTS iterations, and an animation's frames, as tasks on a cluster.

Iteration k of a frame is a deterministic function of (scene, settings, seed, k)
(:mod:`.integrators.ercuts.progressive`), and a render of N iterations is the fold, in iteration
order, of the iterations' films by :meth:`Film.merge <ercuts_core.film.Film.merge>` (one pass each:
equal weights). Here every iteration is a Ray task (Moritz et al. 2018, "Ray: a distributed
framework for emerging AI applications"; ``ray`` is the optional ``cluster`` extra):

* **Scene.** A frame (:class:`FrameJob`) ships its description once, as ``.npz`` bytes put into
  Ray's object store; each task reads it from its node's shared memory, builds its own embreex
  BVH and renders iteration k (:func:`~ercuts_core.render.render_film` with ``iterations=1,
  iteration_start=k``: seed and VPL clamp of (seed, k)). Workers need numpy + embreex (+ scipy,
  OpenEXR), not Blender; the driver's ``ercuts_core`` is shipped with each task
  (``runtime_env`` ``py_modules``), so every node runs the same core.
* **Merge.** The driver folds the returned films (float64 sums) into the frame's film in
  iteration order — a film that arrives early waits for its predecessors — which is exactly the
  fold of a single-process render: the image is bit-identical to ``render()`` of the same
  iterations (``tests/test_cluster.py``). PATH and BDPT frames are one task each.
* **Progress.** ``progress(fraction, message)`` about every :data:`POLL_SECONDS` (merged and
  running iterations) and ``preview(image)`` with the merged image after an iteration, at most
  once per :data:`~ercuts_core.integrators.base.PREVIEW_INTERVAL`; ``progress`` returning False
  cancels every task of the render (``ray.cancel``) and returns the iterations merged so far.
* **Time limit.** ``time_limit`` is the driver's budget from the frame's first task: tasks
  render full-quality iterations (a paced iteration would depend on timing, not only on (seed,
  k)); with ``iterations = 0`` iterations are submitted until the limit. A PATH or BDPT frame's
  one task keeps the limit itself. At the limit the running
  tasks are cancelled and the completed iterations merged in index order; the first iteration is
  always waited for, so an image has at least one.
* **Faults.** A task whose worker process dies is re-run by Ray (``max_retries`` =
  :data:`MAX_RETRIES`) with the same arguments, so the same seed and the same film. A task that
  raises is not retried (its error is deterministic): the other tasks are cancelled and
  :class:`ClusterError` names the scene, frame and iteration with the worker's error. With a
  ``checkpoint`` path the merged film, its sample count and the iteration list are written
  atomically after every merge (:mod:`ercuts_core.checkpoint`); a later render of the same scene
  and settings with that path resumes from it, and an interrupted driver loses only the
  iterations that were running.
* **Memory.** Each task asks Ray for the memory the core's plan estimates
  (:func:`~ercuts_core.memory.plan_for`), so a node runs no more iterations at once than its
  memory holds.
"""
from __future__ import annotations

import io
import itertools
import logging
import os
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from .checkpoint import checkpoint_key, load_checkpoint, resumable, save_checkpoint
from .description import SceneDescription, load_npz, save_npz
from .film import Film
from .integrators.base import Clock, Preview, Progress
from .result import RenderResult
from .settings import RenderSettings

#: Times Ray re-runs a task whose worker died (the same arguments: the same seed).
MAX_RETRIES = 3
#: CPUs Ray reserves per task; the task's ray tracer uses as many threads.
CPUS_PER_TASK = 1
#: Seconds between two polls of the running tasks (progress, cancel, time limit).
POLL_SECONDS = 0.25
#: Tasks in flight per cluster CPU (one queued behind each running one keeps workers busy).
IN_FLIGHT_PER_CPU = 2
#: Memory asked per task on top of the plan's estimate: the worker process and its imports.
TASK_OVERHEAD_BYTES = 200 << 20
#: Seconds between two checkpoint writes of a frame (a write is the whole film: ~230 bytes a
#: pixel); a stop, an exception in the driver and the frame's end always write.
CHECKPOINT_SECONDS = 10.0
#: The job's runtime environment: this ``ercuts_core`` package, uploaded to the cluster once
#: per connection (cached by content), so every worker runs the driver's core.
RUNTIME_ENV = {"py_modules": [os.path.dirname(os.path.abspath(__file__))]}
#: Install hint when ``ray`` is missing.
INSTALL_HINT = "cluster rendering needs the 'ray' package: pip install 'ercuts-core[cluster]'"


class ClusterError(RuntimeError):
    """A render on the cluster failed: the message names the scene, frame and iteration."""


# --------------------------------------------------------------------------- connection
def require_ray():
    """The ``ray`` module, or :class:`ClusterError` with :data:`INSTALL_HINT`."""
    try:
        import ray
    except ImportError as exc:
        raise ClusterError(f"{INSTALL_HINT} ({exc})") from None
    return ray


@contextmanager
def connect(address: str, num_cpus: int | None = None):
    """Yield ``ray`` connected to the cluster ``address`` (:attr:`RenderSettings.cluster`):
    'local' starts a cluster on this machine (``num_cpus``, default all) and stops it at the
    end; 'auto', 'host:port' and 'ray://host:port' join a running one (and leave it at the end).
    The driver's ``ercuts_core`` goes to the workers with the job (:data:`RUNTIME_ENV`). A
    process already connected (``ray.is_initialized()``) stays connected as it is: its job
    must make ``ercuts_core`` importable on the workers (e.g. ``runtime_env=RUNTIME_ENV``)."""
    ray = require_ray()
    if ray.is_initialized():
        yield ray
        return
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")    # no usage report to the internet
    quiet = dict(logging_level=logging.WARNING, log_to_driver=False, runtime_env=RUNTIME_ENV)
    try:
        if address == "local":
            ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, **quiet)
        elif address.startswith("ray://"):
            ray.init(address=address, logging_level=logging.WARNING, runtime_env=RUNTIME_ENV)
        else:
            ray.init(address=address, **quiet)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise ClusterError(f"cannot connect to the Ray cluster {address!r}: {exc}") from exc
    try:
        yield ray
    finally:
        ray.shutdown()


# --------------------------------------------------------------------------- work units
@dataclass
class FrameJob:
    """One frame for the cluster.

    Attributes:
        npz: the scene description as ``.npz`` bytes (:func:`~ercuts_core.description.save_npz`).
        settings: its render settings (``cluster`` and ``time_limit`` stay with the driver).
        scene: the scene's name (error messages, progress).
        frame: the frame number (error messages, progress).
        checkpoint: path of the frame's resumable checkpoint, or None.
        memory_bytes: memory to ask Ray for per task, or None (no request).
        window: (x0, y0, w, h) of the rendered window, for a result before any iteration came
            back (a cancel), or None.
        full_size: (width, height) of the full frame, or None.
    """

    npz: bytes
    settings: RenderSettings
    scene: str = "scene"
    frame: int = 1
    checkpoint: str | None = None
    memory_bytes: int | None = None
    window: tuple[int, int, int, int] | None = None
    full_size: tuple[int, int] | None = None

    @property
    def label(self) -> str:
        return f"scene {self.scene!r} frame {self.frame}"


def npz_bytes(desc: SceneDescription) -> bytes:
    """``desc`` as the bytes of its ``.npz`` file (:func:`~ercuts_core.description.save_npz`)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="ercuts-") as tmp:
        path = os.path.join(tmp, "scene.npz")
        save_npz(desc, path)
        with open(path, "rb") as fh:
            return fh.read()


def frame_job(desc: SceneDescription, settings: RenderSettings, scene: str = "scene", frame: int = 1,
              checkpoint: str | None = None) -> FrameJob:
    """A :class:`FrameJob` for ``desc``, validated here (a :class:`~ercuts_core.validate.SceneError`
    is raised on the driver, before anything is shipped), with the memory request of the core's
    plan and the window."""
    from .camera import render_window
    from .memory import plan_for
    from .validate import sanitize

    clean = sanitize(desc).desc
    memory = plan_for(clean, settings)
    window = render_window(clean.camera)
    return FrameJob(npz_bytes(desc), settings, scene, frame, checkpoint,
                    memory_bytes=int(memory.total) + TASK_OVERHEAD_BYTES, window=window.rect,
                    full_size=(clean.camera.width, clean.camera.height))


def iteration_indices(settings: RenderSettings) -> Iterator[int]:
    """The iterations a render consists of, in merge order: ERCUTS ``iteration_start`` …
    ``iteration_start + iterations − 1`` (one without a time limit when ``iterations`` is 0,
    endless with one: the driver stops at the limit); PATH and BDPT: one task, 0."""
    if settings.integrator != "ERCUTS":
        yield 0
        return
    k = settings.iteration_start
    n = settings.iterations or (0 if settings.time_limit > 0 else 1)
    while n == 0 or k < settings.iteration_start + n:
        yield k
        k += 1


@dataclass
class IterationResult:
    """What a task returns: iteration ``k``'s film (float64 sums) and its statistics."""

    k: int
    film: Film
    stats: dict
    timings: dict
    issues: list
    full_size: tuple[int, int]
    cancelled: bool = False
    stopped_by: str | None = None
    pid: int = 0                             # the worker process that rendered it
    max_rss_mb: float = 0.0                  # its peak resident memory so far (MiB)

    @property
    def nbytes(self) -> int:
        """Bytes of the film's arrays (what a task ships back)."""
        f = self.film
        arrays = [v for v in vars(f).values() if isinstance(v, np.ndarray)]
        arrays += [np.asarray(v) for v in f.aov_sum.values()]
        return int(sum(a.nbytes for a in arrays))


def task_settings(settings: RenderSettings) -> RenderSettings:
    """What a task renders with: never on a cluster itself, and for ERCUTS without the time
    limit, which stays the driver's (a paced iteration would depend on timing); a PATH or BDPT
    frame is one task, which keeps it."""
    if settings.integrator == "ERCUTS":
        return settings.replace(cluster="", time_limit=0.0)
    return settings.replace(cluster="")


def render_iteration(npz, settings: dict, k: int) -> IterationResult:
    """The task: iteration ``k`` of the scene ``npz`` (bytes or uint8 array) with ``settings``
    (:meth:`RenderSettings.to_dict`); ERCUTS renders that one iteration, PATH and BDPT the frame.
    Runs in a Ray worker (or anywhere): numpy + embreex only."""
    from .render import render_film

    s = RenderSettings.from_dict(settings)
    if s.integrator == "ERCUTS":
        s = s.replace(iterations=1, iteration_start=k)
    if s.threads == 0:
        s = s.replace(threads=CPUS_PER_TASK)
    film, result = render_film(load_npz(io.BytesIO(np.asarray(npz, dtype=np.uint8).tobytes())), s)
    return IterationResult(k, film, dict(result.stats), dict(result.timings), list(result.issues),
                           tuple(result.full_size), result.cancelled, result.stopped_by, os.getpid(),
                           _max_rss_mb())


def _max_rss_mb() -> float:
    """This process's peak resident set size in MiB (Linux reports KiB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


# --------------------------------------------------------------------------- one frame's state
@dataclass
class _FrameState:
    """The driver's bookkeeping for one frame: what is submitted, merged and waiting."""

    job: FrameJob
    indices: Iterator[int]
    key: str
    ref: object = None                       # the description in the object store
    clock: Clock | None = None
    film: Film | None = None
    done: list[int] = field(default_factory=list)         # merged, in order
    waiting: dict[int, IterationResult] = field(default_factory=dict)
    expected: list[int] = field(default_factory=list)     # submitted (or resumed), in order
    exhausted: bool = False                  # no more iterations to submit
    first: IterationResult | None = None     # the lowest merged iteration (stats, issues)
    timings: dict = field(default_factory=dict)
    result_bytes: list[int] = field(default_factory=list)
    stopped: str | None = None               # 'time_limit' once the frame's limit stopped it
    rays: int = 0
    max_rss_mb: float = 0.0
    pids: set = field(default_factory=set)
    resumed: int = 0                         # iterations taken from the checkpoint
    saved: int = 0                           # iterations in the checkpoint on disk
    saved_at: float = 0.0                    # perf_counter of that write

    def next_index(self) -> int | None:
        if self.exhausted:
            return None
        k = next(self.indices, None)
        if k is None:
            self.exhausted = True
        return k

    def add(self, res: IterationResult) -> bool:
        """Keep ``res``; merge every result that is next in order. Returns whether any merged."""
        self.waiting[res.k] = res
        self.result_bytes.append(res.nbytes)
        merged = False
        while len(self.done) < len(self.expected) and self.expected[len(self.done)] in self.waiting:
            self._merge(self.waiting.pop(self.expected[len(self.done)]))
            merged = True
        return merged

    def _merge(self, res: IterationResult) -> None:
        if self.film is None:
            self.film = Film(res.film.window)
        self.film.merge(res.film)
        self.done.append(res.k)
        if self.first is None:
            self.first = res
        self.rays += int(res.stats.get("rays", 0))
        self.max_rss_mb = max(self.max_rss_mb, res.max_rss_mb)
        self.pids.add(res.pid)
        for name, seconds in res.timings.items():
            self.timings[name] = self.timings.get(name, 0.0) + seconds

    def merge_waiting(self) -> None:
        """At a stop: merge the results that still wait for a predecessor, in index order."""
        for k in sorted(self.waiting):
            self._merge(self.waiting.pop(k))

    @property
    def complete(self) -> bool:
        return self.exhausted and len(self.done) == len(self.expected)

    def result(self, stopped_by: str | None) -> RenderResult | None:
        """The frame's :class:`RenderResult` (None when nothing was merged and no window is known)."""
        job = self.job
        film = self.film
        if film is None:
            if job.window is None:
                return None
            from .camera import Window
            film = Film(Window(*job.window))
        first = self.first
        stats = dict(first.stats) if first else {}
        stats.update(iterations=len(self.done), samples=film.passes_done, nonfinite_samples=film.nonfinite,
                     rays=self.rays, cluster_workers=len(self.pids),
                     cluster_worker_max_rss_mb=self.max_rss_mb, cluster_resumed_iterations=self.resumed,
                     cluster_scene_bytes=len(job.npz),
                     cluster_result_bytes=float(np.mean(self.result_bytes)) if self.result_bytes else 0.0)
        timings = dict(self.timings)
        timings["total"] = time.perf_counter() - self.clock.start if self.clock else 0.0
        return RenderResult(
            image=film.image(), window=film.window.rect,
            full_size=first.full_size if first else (job.full_size or film.window.rect[2:]),
            timings=timings, stats=stats, issues=list(first.issues) if first else [],
            cancelled=stopped_by is not None, aovs=film.aovs(), stopped_by=stopped_by)


# --------------------------------------------------------------------------- the driver
class Driver:
    """Runs :class:`FrameJob` s on the connected cluster (module docstring).

    Args:
        ray: the connected ``ray`` module (:func:`connect`).
        progress: ``progress(fraction, message) -> bool | None``; False cancels.
        preview: ``preview(image)`` with the merged image of the frame being rendered.
        frames_total: number of frames (progress), if known.
    """

    def __init__(self, ray, progress: Progress | None = None, preview: Preview | None = None,
                 frames_total: int | None = None):
        self.ray = ray
        self.progress, self.preview = progress, preview
        self.frames_total = frames_total
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.cpus = max(cpus, 1)
        self.max_in_flight = max(2, IN_FLIGHT_PER_CPU * self.cpus // CPUS_PER_TASK)
        self.largest_node_memory = max((n["Resources"].get("memory", 0) for n in ray.nodes() if n["Alive"]),
                                       default=0)
        self.task = ray.remote(render_iteration)
        self.in_flight: dict = {}            # ObjectRef -> (_FrameState, k)
        self.frames_done = 0
        self.jobs_done = False
        self.stopped_by: str | None = None

    # ---------------------------------------------------------------- public
    def run(self, jobs: Iterable[FrameJob],
            on_frame: Callable[[FrameJob, RenderResult], None] | None = None) -> list[RenderResult | None]:
        """Render ``jobs`` (pulled one at a time, as the cluster has room: an exporter can
        produce them lazily); ``on_frame(job, result)`` after each completed frame. Returns
        the results not handed to ``on_frame``, in order: every frame's without it, else only
        those of frames a cancel stopped (None for one with nothing merged and no window), so
        a long animation does not pile up its images here.

        Raises:
            ClusterError: a task raised (the others are cancelled).
            CheckpointMismatch: a frame's checkpoint belongs to another scene or settings.
        """
        jobs = iter(jobs)
        active: list[_FrameState] = []
        results: list[RenderResult | None] = []
        try:
            while True:
                self._fill(jobs, active)
                if not active:
                    break
                self._collect()
                self._poll(active)
                while active and (active[0].complete or self.stopped_by):
                    state = active.pop(0)
                    res = self._finish(state)
                    if res is not None and on_frame is not None and not self.stopped_by:
                        on_frame(state.job, res)
                    else:
                        results.append(res)
                    self.frames_done += 1
                if self.stopped_by:
                    break
        finally:
            self._cancel_all()
            for state in active:       # stopped or interrupted: keep what was merged
                self._checkpoint(state, force=True)
        return results

    # ---------------------------------------------------------------- submission
    def _fill(self, jobs: Iterator[FrameJob], active: list[_FrameState]) -> None:
        """Submit tasks while fewer than :attr:`max_in_flight` run, pulling the next frame from
        ``jobs`` when the open ones have nothing left to submit."""
        while len(self.in_flight) < self.max_in_flight:
            state = next((s for s in active if not s.exhausted), None)
            if state is None:
                job = None if self.jobs_done else next(jobs, None)
                if job is None:
                    self.jobs_done = True
                    return
                active.append(self._open(job))
                continue
            if state.clock.expired():
                state.exhausted = True          # the time limit: no new iterations
                continue
            k = state.next_index()
            if k is not None:
                self._submit(state, k)

    def _open(self, job: FrameJob) -> _FrameState:
        """A frame's state: its checkpoint resumed, its description put into the object store."""
        s = job.settings
        state = _FrameState(job, iteration_indices(s), checkpoint_key(job.npz, s))
        state.clock = Clock(s.time_limit, None, self.preview)
        if job.checkpoint:
            saved = load_checkpoint(job.checkpoint, state.key)
            if saved is not None:
                state.film, done = saved
                resumable(done, list(itertools.islice(state.indices, len(done))), job.checkpoint)
                state.done, state.expected = list(done), list(done)
                state.resumed = state.saved = len(done)
        state.ref = self.ray.put(np.frombuffer(job.npz, dtype=np.uint8))
        return state

    def _submit(self, state: _FrameState, k: int) -> None:
        job = state.job
        options = dict(num_cpus=CPUS_PER_TASK, max_retries=MAX_RETRIES, retry_exceptions=False,
                       name=f"ercuts {job.scene} f{job.frame} it{k}")
        if job.memory_bytes and self.largest_node_memory:
            options["memory"] = int(min(job.memory_bytes, 0.9 * self.largest_node_memory))
        settings = task_settings(job.settings).to_dict()
        ref = self.task.options(**options).remote(state.ref, settings, k)
        self.in_flight[ref] = (state, k)
        state.expected.append(k)

    # ---------------------------------------------------------------- results
    def _collect(self) -> None:
        """Wait up to :data:`POLL_SECONDS` for tasks; merge what came back."""
        if not self.in_flight:
            return
        refs = list(self.in_flight)
        ready, _ = self.ray.wait(refs, num_returns=len(refs), timeout=POLL_SECONDS)
        for ref in ready:
            state, k = self.in_flight.pop(ref)
            try:
                res = self.ray.get(ref)
            except Exception as exc:    # noqa: BLE001 - every task failure names its frame
                self._cancel_all()
                raise ClusterError(f"{state.job.label}, iteration {k}: {_cause(exc)}") from exc
            if state.add(res):
                self._checkpoint(state)
                state.clock.show(state.film.image)

    def _checkpoint(self, state: _FrameState, force: bool = False) -> None:
        """Write the frame's checkpoint if it has merged iterations not on disk yet, at most every
        :data:`CHECKPOINT_SECONDS` unless ``force`` (the end of the frame, a stop, an exception)."""
        if not state.job.checkpoint or state.film is None or len(state.done) == state.saved:
            return
        if not force and time.perf_counter() - state.saved_at < CHECKPOINT_SECONDS:
            return
        save_checkpoint(state.job.checkpoint, state.film, state.done, state.key)
        state.saved, state.saved_at = len(state.done), time.perf_counter()

    def _poll(self, active: list[_FrameState]) -> None:
        """Progress and cancel; the time limit of each open frame."""
        for state in active:
            if state.clock.expired() and state.done and not state.complete:
                self._stop_frame(state)
        if not active:
            return
        state = active[0]
        n_target = state.job.settings.iterations or None
        running = sum(1 for s, _ in self.in_flight.values() if s is state)
        merged = len(state.done)
        if n_target and state.job.settings.integrator == "ERCUTS":
            f = merged / n_target
        elif state.clock.deadline is not None:
            clock = state.clock
            f = min((time.perf_counter() - clock.start) / (clock.deadline - clock.start), 1.0)
        else:
            f = merged / max(len(state.expected), 1)
        if self.frames_total:
            f = (self.frames_done + f) / self.frames_total
        message = (f"Cluster: {state.job.label}: {merged} iteration{'s' * (merged != 1)} merged, "
                   f"{running} running on {self.cpus} CPUs")
        if self.progress is not None and self.progress(float(f), message) is False:
            self.stopped_by = "cancel"

    def _stop_frame(self, state: _FrameState) -> None:
        """The frame's time limit: cancel its running tasks, merge what came back."""
        state.exhausted = True
        for ref, (s, k) in list(self.in_flight.items()):
            if s is state:
                self.ray.cancel(ref)
                del self.in_flight[ref]
                state.expected.remove(k)
        self._checkpoint(state, force=True)     # before the out-of-order merge: a prefix
        state.merge_waiting()
        state.expected = list(state.done)
        state.stopped = "time_limit"

    def _finish(self, state: _FrameState) -> RenderResult | None:
        """The result of a completed (or, after a cancel, an interrupted) frame."""
        if self.stopped_by:
            for ref, (s, _) in list(self.in_flight.items()):
                if s is state:
                    self.ray.cancel(ref)
                    del self.in_flight[ref]
            self._checkpoint(state, force=True)
            state.merge_waiting()
        state.ref = None                                   # frees the description
        task_stop = state.first.stopped_by if state.first else None     # a PATH/BDPT frame's own limit
        return state.result(self.stopped_by or state.stopped or task_stop)

    def _cancel_all(self) -> None:
        for ref in list(self.in_flight):
            try:
                self.ray.cancel(ref)
            except Exception:   # noqa: BLE001 - a task that finished meanwhile cannot be cancelled
                pass
        self.in_flight.clear()


def _cause(exc: BaseException) -> str:
    """A task's failure in one line: the worker's own exception (type and message) when it
    raised, else Ray's (a worker that died more than :data:`MAX_RETRIES` times, …)."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, BaseException):
        return f"{type(cause).__name__}: {cause}"
    return f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"




# --------------------------------------------------------------------------- entry points
def render(desc: SceneDescription, settings: RenderSettings, progress: Progress | None = None,
           preview: Preview | None = None, scene: str = "scene", frame: int = 1,
           checkpoint: str | None = None) -> RenderResult:
    """:func:`ercuts_core.render` on the cluster ``settings.cluster`` ('' is taken as 'local'):
    the same image for the same iterations (module docstring), ``checkpoint`` to resume from.

    Raises:
        SceneError: the scene cannot be rendered (validated here, before anything is shipped).
        ClusterError: no ``ray``, no cluster at the address, or a task raised.
    """
    job = frame_job(desc, settings, scene, frame, checkpoint)
    with connect(settings.cluster or "local") as ray:
        (result,) = Driver(ray, progress, preview).run([job])
    return result


def render_frames(jobs: Iterable[FrameJob], address: str, on_frame: Callable[[FrameJob, RenderResult], None],
                  progress: Progress | None = None, frames_total: int | None = None) -> list:
    """Render an animation's frames on the cluster at ``address``; ``on_frame(job, result)``
    writes each completed frame (``jobs`` may be a generator: frames are exported while the
    cluster renders the earlier ones). Returns the results of frames a cancel stopped."""
    with connect(address) as ray:
        return Driver(ray, progress, None, frames_total).run(jobs, on_frame)
