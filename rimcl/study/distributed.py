"""Studies over many processes, GPUs and machines with Dask distributed.

:func:`measure_cases` measures the cases of a study (:func:`rimcl.study.run.run_study` with a
``scheduler``) as Dask tasks, one per (case, shard of tracers). Tracers are independent
and every shard sees the same tracers, rays and random numbers as the whole run
(:func:`rimcl.ptv.measure.run_render` with ``shard=``), so the merged tables equal the
single-process ones bit for bit, whatever the number of workers.

Workers
    :class:`RimclPlugin` gives every worker its OpenCL device and context
    (:func:`worker_device`) and opens the field file once, by path; the loaded frames of
    the latest case stay in memory (and on the device) for the worker's next shard. Tasks
    carry only the case's :class:`rimcl.scene.config.MeasureConfig` (a small frozen
    object), the scene's stamp (JSON text), the case name, the shard range and file paths:
    nothing OpenCL is pickled and the field never travels through the scheduler, so the
    field file and the study directory must be on a filesystem every worker sees.

Files (under the study directory)
    ``shards/<case>/<first>-<stop>.h5``: a ``rimcl render`` file of tracers
    ``first..stop-1``, written atomically by the worker that measured it, plus a group
    ``reference`` holding that shard's :class:`rimcl.ptv.render_file.Reference` (true tracks and
    reference images). When every shard of a case is on disk, the client merges them in
    shard order (:func:`rimcl.ptv.render_file.merge_results`) into ``cases/<case>.h5``
    (atomically). A lost worker loses only the shard it was measuring (Dask runs it
    again elsewhere); a rerun, after a killed client too, measures only missing shards.

The reference
    The reference images depend on the shard and the threshold, not on the case. As
    :func:`rimcl.study.run.run_study` does per threshold, the first case of each threshold
    measures it, per shard; the later cases' tasks of that shard wait for that task and
    read the reference from its shard file. So the reference is computed once per
    (threshold, shard) whichever worker runs what, it survives the worker that made it,
    and no task waits for more than one other.
"""

import contextlib
import dataclasses
import json
import logging
import os
import re
import signal
import threading
import time
import uuid
from pathlib import Path

from rimcl.core.atomic import atomic_path
from rimcl.core.errors import RimclError
from rimcl.core.tables_h5 import read_table
from rimcl.study.scheduler import _import_distributed, check_scheduler, parse_scheduler

try:
    from distributed import WorkerPlugin
except ImportError:  # the optional extra is missing: connect() says so in one line
    WorkerPlugin = object

SHARD_DIR = "shards"
#: Host memory (bytes) a worker may keep of a case's loaded frames for its next shard.
FRAME_CACHE_BYTES = 4 << 30


def shard_ranges(count, size):
    """Consecutive ``(first, stop)`` tracer ranges of at most ``size`` tracers tiling
    ``0..count``."""
    return [(first, min(first + size, count)) for first in range(0, count, size)]


def shard_path(out_dir, case, shard):
    """File of one shard of one case in a study directory."""
    first, stop = shard
    return Path(out_dir) / SHARD_DIR / case / f"{first}-{stop}.h5"


def _write_reference(group, reference):
    group.attrs["key"] = json.dumps(reference.key)
    group.attrs["ray_counts"] = json.dumps(reference.ray_counts)
    group.attrs["ray_steps"] = int(reference.ray_steps)
    group.create_dataset("tracks", data=reference.tracks)
    group.create_dataset("outside", data=reference.outside)
    for name in ("true_velocity", "true_acceleration"):
        if getattr(reference, name) is not None:
            group.create_dataset(name, data=getattr(reference, name))
    for group_name, columns in (("images", reference.images), ("floor", reference.floor_images)):
        images = group.create_group(group_name)
        for name, values in columns.items():
            images.create_dataset(name, data=values)


def _read_reference(group):
    from rimcl.ptv.render_file import Reference

    if "floor" not in group:
        raise RimclError(
            f"{group.file.filename}: a shard file of an older rimcl (no noise-floor exposure); "
            "rerun the study with --force"
        )
    return Reference(
        key=json.loads(group.attrs["key"]),
        tracks=group["tracks"][()],
        true_velocity=group["true_velocity"][()] if "true_velocity" in group else None,
        true_acceleration=group["true_acceleration"][()] if "true_acceleration" in group else None,
        outside=group["outside"][()],
        images={name: values[()] for name, values in group["images"].items()},
        floor_images={name: values[()] for name, values in group["floor"].items()},
        ray_counts=json.loads(group.attrs["ray_counts"]),
        ray_steps=int(group.attrs["ray_steps"]),
    )


def scene_stamp(study):
    """What a shard file must have been measured for: the study's scene without the keys
    that do not change the numbers (:data:`rimcl.study.case_files.RUN_ONLY_KEYS`), as JSON
    text."""
    from rimcl.study.case_files import comparable_scene

    return json.dumps(comparable_scene(study), sort_keys=True)


def _stamp_of(path):
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            return h5.attrs.get("study_scene")
    except OSError:
        return None


def write_shard(path, result, stamp=""):
    """Write one shard's :class:`rimcl.ptv.render_file.RenderResult` and its reference, atomically.

    Parameters
    ----------
    path : str or Path
    result : RenderResult
        From :func:`rimcl.ptv.measure.run_render` with ``shard=``.
    stamp : str
        :func:`scene_stamp` of the study (root attribute ``study_scene``).
    """
    import h5py

    from rimcl.ptv.render_file import write_render

    with atomic_path(path, overwrite=True) as tmp:
        write_render(tmp, result, overwrite=True)
        with h5py.File(tmp, "a") as h5:
            h5.attrs["study_scene"] = stamp
            _write_reference(h5.create_group("reference"), result.reference)


def read_shard(path):
    """A shard file (:func:`write_shard`) as a :class:`rimcl.ptv.render_file.RenderResult`.

    Returns
    -------
    RenderResult
        ``device`` and ``frame_image`` are None; the device the shard ran on is the
        file's ``device`` attribute.
    """
    import h5py

    from rimcl.ptv.render_file import RenderResult

    provenance = ("config", "versions", "device", "timings_s", "study_scene")
    try:
        h5 = h5py.File(path, "r")
    except OSError as exc:
        raise RimclError(f"{path}: not a readable shard file ({exc})") from None
    with h5:
        if "reference" not in h5:
            raise RimclError(f"{path} is not a shard file of a distributed study (no reference)")

        def table(name):
            if name not in h5:
                return None
            # 1-D frame-major columns, as the run made them: merged files get their own labels
            return read_table(h5[name])

        return RenderResult(
            attrs={k: v for k, v in h5.attrs.items() if k not in provenance},
            config=json.loads(h5.attrs["config"]),
            tracers=table("tracers"),
            kinematics={name: table(name) for name in KINEMATIC_TABLES},
            rays=table("rays"),
            ray_attrs=dict(h5["rays"].attrs),
            reference=_read_reference(h5["reference"]),
            timings=json.loads(h5.attrs["timings_s"]),
            frame_image=None,
            device=None,
        )


#: The render file's tables of velocities and accelerations
#: (rimcl.ptv.kinematics.kinematics_tables).
KINEMATIC_TABLES = ("velocity", "acceleration", "velocity_fit", "acceleration_fit")


def merge_shards(path, shard_paths):
    """Merge the shard files of one case, in order, into its render file (atomically).

    The merged file records the device of the first shard, as a single-process run
    records its device.

    Parameters
    ----------
    path : str or Path
        ``cases/<case>.h5``.
    shard_paths : sequence of Path
        Shards tiling all tracers, in tracer order.
    """
    import h5py

    from rimcl.ptv.render_file import merge_results, write_render

    merged = merge_results([read_shard(p) for p in shard_paths])
    with h5py.File(shard_paths[0], "r") as h5:
        device = h5.attrs.get("device")
    with atomic_path(path, overwrite=True) as tmp:
        write_render(tmp, merged, overwrite=True)
        if device is not None:
            with h5py.File(tmp, "a") as h5:
                h5.attrs["device"] = device


def worker_index(name):
    """The index of a worker from its Dask name: an integer (``LocalCluster``: 0..N-1) or a
    name ending in ``-<integer>`` (``dask worker --name gpu-1``); None otherwise."""
    if isinstance(name, int):
        return name
    match = re.search(r"(?:^|-)(\d+)$", str(name))
    return None if match is None else int(match.group(1))


def worker_device(name=None, spec=None):
    """The OpenCL device of one worker.

    In order: ``RIMCL_DEVICE`` in the worker's environment (the device belongs to the
    worker, so this beats the scene); ``spec`` (the scene's ``run.device``); for a worker
    with an index (:func:`worker_index`) on a machine with GPUs, GPU ``index mod count``
    (one worker per GPU); else :func:`rimcl.core.device.select_device`'s default.

    Parameters
    ----------
    name : int or str, optional
        The worker's Dask name.
    spec : str, optional

    Returns
    -------
    pyopencl.Device
    """
    from rimcl.core.device import list_devices, select_device

    chosen = os.environ.get("RIMCL_DEVICE") or spec or None
    index = worker_index(name)
    if chosen is None and index is not None:
        gpus = [d["index"] for d in list_devices() if d["usable"] and "GPU" in d["type"]]
        if gpus:
            chosen = gpus[index % len(gpus)]
    return select_device(chosen)


class _CachedFrames:
    """A field file whose frames of the latest case stay loaded (and uploaded) for the
    next shard, within ``budget`` bytes of host memory; everything else is the file's."""

    def __init__(self, source, budget):
        self._source = source
        self._budget = budget
        self._frames = {}

    def __getattr__(self, name):
        return getattr(self._source, name)

    def field(self, frame=0, k_rho=None):
        """:meth:`rimcl.fields.field_reader.FieldFile.field`, kept for the next call."""
        key = (int(frame), k_rho)
        if key not in self._frames:
            if any(k_rho != cached for _, cached in self._frames):
                self._frames.clear()  # another case: its frames will not come back soon
            field = self._source.field(frame, k_rho)
            size = field.delta_n.nbytes + field.gradient.nbytes
            if size * (len(self._frames) + 1) > self._budget:
                return field
            self._frames[key] = field
        return self._frames[key]


class RimclPlugin(WorkerPlugin):
    """Per-worker state of a distributed study: the OpenCL device and the open field.

    Parameters
    ----------
    field_path : str
        Absolute path of the field file, the same on every worker ("" = the shipped
        sample).
    device_spec : str, optional
        The scene's ``run.device`` (see :func:`worker_device`).
    frame_cache_bytes : int
        See :data:`FRAME_CACHE_BYTES`.
    """

    def __init__(self, field_path, device_spec=None, frame_cache_bytes=FRAME_CACHE_BYTES):
        self.field_path = field_path
        self.device_spec = device_spec
        self.frame_cache_bytes = frame_cache_bytes
        # one plugin per field and device: studies of other fields sharing a scheduler
        # keep theirs, and the same study connecting again replaces its own
        self.name = plugin_name(field_path, device_spec)

    def setup(self, worker):
        """Choose the device, create its context, open the field file."""
        from rimcl.core.device import context_for
        from rimcl.fields.field_reader import FieldFile
        from rimcl.fields.sample import sample_path

        self.device = worker_device(worker.name, self.device_spec)
        context_for(self.device)
        self.file = FieldFile(self.field_path or sample_path())
        self.source = _CachedFrames(self.file, self.frame_cache_bytes)
        # a worker started with several threads still measures one shard at a time:
        # the shards share the device, its queue and the open file
        self.lock = threading.Lock()

    def teardown(self, worker):
        """Close the field file."""
        self.file.close()


def plugin_name(field_path, device_spec=None):
    """Name of the :class:`RimclPlugin` of a field file and a scene's ``run.device``."""
    return f"rimcl:{field_path}:{device_spec or ''}"


def _plugin(name, worker=None):
    from distributed import get_worker

    plugin = (worker or get_worker()).plugins.get(name)
    if plugin is None or not hasattr(plugin, "source"):
        raise RimclError(f"this Dask worker has no working plugin {name} (see its log)")
    return plugin


def worker_description(name, dask_worker):
    """The device name of a worker's plugin ``name`` (``Client.run`` passes the worker)."""
    return _plugin(name, dask_worker).device.name.strip()


def _reference_for(path, plugin):
    """The reference stored in shard file ``path``, or None if another kind of device made
    it (a rerun on other workers): this worker then measures its own, as a
    single-process rerun would."""
    import h5py

    from rimcl.core.device import describe_device

    with h5py.File(path, "r") as h5:
        reference = _read_reference(h5["reference"])
    made_on = reference.key.get("trace", {}).get("device")
    return reference if made_on == describe_device(plugin.device) else None


def measure_shard(plugin, config, stamp, case, shard, path, reference_path=None, wait_for=None):
    """One task: measure tracers ``shard`` of ``case`` on this worker into ``path``.

    Parameters
    ----------
    plugin : str
        Name of the worker's :class:`RimclPlugin` (:func:`plugin_name`).
    config : rimcl.scene.config.MeasureConfig
        The case's configuration (:meth:`rimcl.scene.study_config.StudyConfig.measure`).
    stamp : str
        :func:`scene_stamp` of the study, recorded in the shard file.
    case : str
    shard : (int, int)
        Tracers ``first..stop-1``.
    path : str
        Shard file to write (:func:`write_shard`). If it exists, a worker lost after
        writing it already did this task, and nothing is measured.
    reference_path : str, optional
        A shard file of the same shard and threshold to take the reference from; None
        (or a reference made on another kind of device): measure the reference too.
    wait_for : object, optional
        The result of the task that writes ``reference_path``; passing it makes Dask run
        this task after that one. Not used otherwise.

    Returns
    -------
    dict
        ``path``, ``seconds`` (wall time on the worker), ``measured`` (False if the file
        was there).
    """
    from rimcl.ptv.measure import run_render
    from rimcl.study.case_files import SCENE_RECORD

    start = time.perf_counter()
    if Path(path).exists():
        return {"path": path, "seconds": 0.0, "measured": False}
    plugin = _plugin(plugin)
    with plugin.lock:
        config = dataclasses.replace(
            config, run=dataclasses.replace(config.run, device=plugin.device)
        )
        reference = None if reference_path is None else _reference_for(reference_path, plugin)
        # a candidate: a lens camera's reference depends on the case's mean index too
        result = run_render(
            plugin.source,
            case=case,
            config=config,
            reference=None if reference is None else [reference],
            shard=shard,
        )
        result.config[SCENE_RECORD] = json.loads(stamp)
        write_shard(path, result, stamp)
    return {"path": path, "seconds": time.perf_counter() - start, "measured": True}


@contextlib.contextmanager
def _quiet_dask():
    """Dask's own logging at WARNING (a lost worker, not every connection) while it runs
    here, unless asked for more (``rimcl -v``)."""
    logger = logging.getLogger("distributed")
    previous = logger.level
    if logging.getLogger().getEffectiveLevel() > logging.DEBUG:
        logger.setLevel(logging.WARNING)
    try:
        yield
    finally:
        logger.setLevel(previous)


@contextlib.contextmanager
def _sigint_ignored():
    """SIGINT ignored while child processes start (they inherit it), where signals can be
    set (the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def connect(spec, field_path="", device_spec=None, report=None):
    """A Dask client for ``spec``, every worker set up with a :class:`RimclPlugin`.

    ``local:N`` starts a ``LocalCluster`` of N single-threaded worker processes on
    127.0.0.1 (dashboard on loopback, its address reported) and stops it on exit; an
    address connects to a running scheduler.

    Parameters
    ----------
    spec : str
        See :func:`parse_scheduler`.
    field_path : str
        The field file ("" = the shipped sample), made absolute here.
    device_spec : str, optional
        The scene's ``run.device``.
    report : callable, optional
        Called with one line of text per step.

    Yields
    ------
    client : distributed.Client
    plugin : str
        Name of the workers' :class:`RimclPlugin`, for :func:`measure_shard`.
    """
    say = report or (lambda line: None)
    answered = check_scheduler(spec)
    kind, value = parse_scheduler(spec)
    distributed = _import_distributed(spec)
    import dask

    with contextlib.ExitStack() as stack:
        stack.enter_context(_quiet_dask())
        if kind == "local":
            # Dask's nannies set MALLOC_TRIM_THRESHOLD_, which also fixes glibc's mmap
            # threshold: every large NumPy temporary is then mapped and unmapped, and a
            # worker spends a third of its time in the kernel (measured on PoCL)
            stack.enter_context(
                dask.config.set(
                    {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
                )
            )
            # Ctrl-C reaches every process of the terminal's group: workers started with
            # SIGINT ignored leave it to this process, which stops them (one line, not a
            # traceback per worker)
            with _sigint_ignored():
                cluster = stack.enter_context(
                    distributed.LocalCluster(
                        n_workers=value,
                        threads_per_worker=1,
                        processes=True,
                        host="127.0.0.1",
                        dashboard_address="127.0.0.1:0",
                        # each worker holds its own copy of the field: let the OS, not a
                        # per-worker share of the memory, decide what fits
                        memory_limit=0,
                        silence_logs=logging.ERROR,
                    )
                )
            client = stack.enter_context(distributed.Client(cluster))
            say(f"Dask: {answered}; dashboard {cluster.dashboard_link}")
        else:
            try:
                client = stack.enter_context(distributed.Client(value, timeout="30s"))
            except (OSError, TimeoutError) as exc:
                raise RimclError(f"cannot reach the Dask scheduler at {value}: {exc}") from None
            say(f"Dask: {answered}; dashboard {client.dashboard_link}")
        field = str(Path(field_path).resolve()) if field_path else ""
        plugin = RimclPlugin(field, device_spec or None)
        client.register_plugin(plugin)
        devices = sorted(client.run(worker_description, plugin.name).values())
        if devices:
            kinds = {name: devices.count(name) for name in devices}
            say(f"{len(devices)} workers: " + ", ".join(f"{n} x {d}" for d, n in kinds.items()))
        else:
            say("no worker has joined yet: the tasks wait for workers")
        try:
            yield client, plugin.name
        except KeyboardInterrupt:
            # stopping busy workers is what Ctrl-C asked for: not a warning per worker
            logging.getLogger("distributed").setLevel(logging.ERROR)
            raise


def _remove_orphans(directory):
    """Temporary files of workers killed while writing (their tasks were run again)."""
    for orphan in Path(directory).glob(".*.part"):
        orphan.unlink(missing_ok=True)


def measure_cases(
    study, out_dir, scheduler, *, force=False, progress=False, report=None, connected=None
):
    """Measure every case of a study on a Dask cluster into ``cases/<case>.h5``.

    Cases whose file exists are kept (unless ``force``); of the others, only shards
    without a file are measured. Each case file is written as soon as its last shard is.

    Parameters
    ----------
    study : rimcl.scene.study_config.StudyConfig
        ``study.run.shard_tracers`` sets the shard size.
    out_dir : Path
        The study directory (see :mod:`rimcl.study.run`).
    scheduler : str
        See :func:`parse_scheduler`.
    force : bool
        Measure every shard again.
    progress : bool
        A progress bar of finished shards (on a terminal).
    report : callable, optional
        Called with one line of text per step.
    connected : callable, optional
        Called without arguments once the workers are set up, before any task (the study
        writes its ``scene.toml`` then, not for a run that could not connect).

    Returns
    -------
    ran, skipped : list of str
        Cases merged in this run, and cases found finished.
    seconds : dict of str to float
        Worker time of each case merged in this run (s), summed over its shards.
    """
    from rimcl.study.case_files import case_path, check_case_file

    parse_scheduler(scheduler)  # a bad spec or a missing Dask, before anything is touched
    _import_distributed(scheduler)
    say = report or (lambda line: None)
    out_dir = Path(out_dir)
    names = study.names
    shards = shard_ranges(study.shared.tracers.count, study.run.shard_tracers)
    position = {name: index for index, name in enumerate(names, start=1)}
    ran, skipped, seconds = [], [], {}
    todo = []
    for name in names:
        path = case_path(out_dir, name)
        if path.exists() and not force and check_case_file(path, study, name) is None:
            skipped.append(name)
            say(f"[{position[name]}/{len(names)}] {name}: finished earlier, kept")
        else:
            todo.append(name)
    if not todo:
        if connected is not None:
            connected()
        return ran, skipped, seconds
    stamp = scene_stamp(study)
    for name in names:
        for path in shard_paths(out_dir, name, shards):
            # another scene's shards (left by a forced single-process run) are not kept
            if path.exists() and ((force and name in todo) or _stamp_of(path) != stamp):
                path.unlink()
    for name in todo:
        (out_dir / SHARD_DIR / name).mkdir(parents=True, exist_ok=True)

    field, device = study.field_path, study.shared.run.device
    with connect(scheduler, field, device, say) as (client, plugin):
        if connected is not None:
            connected()
        futures, waiting = _submit(client, plugin, study, stamp, out_dir, todo, shards)
        pending = {name: len(tasks) for name, tasks in waiting.items()}
        worker_seconds = dict.fromkeys(todo, 0.0)

        bar = None
        if progress and futures:
            from tqdm.auto import tqdm

            bar = tqdm(total=len(futures), unit="shard", desc="shards", disable=None)

        def finish(name):
            merge_shards(case_path(out_dir, name), shard_paths(out_dir, name, shards))
            _remove_orphans(out_dir / SHARD_DIR / name)
            ran.append(name)
            seconds[name] = worker_seconds[name]
            line = (
                f"[{position[name]}/{len(names)}] {name}: {len(shards)} shard files merged "
                f"({len(waiting[name])} measured now, {worker_seconds[name]:.1f} s of "
                "worker time)"
            )
            with contextlib.nullcontext() if bar is None else bar.external_write_mode():
                say(line)  # above the bar, not through it

        try:
            from distributed import as_completed

            for name in todo:
                if not pending[name]:
                    finish(name)
            for future in as_completed(futures):
                name = futures[future]
                done = _result(future, name)
                worker_seconds[name] += done["seconds"]
                pending[name] -= 1
                if bar is not None:
                    bar.update(1)
                if not pending[name]:
                    finish(name)
        finally:
            if bar is not None:
                bar.close()
    ran.sort(key=position.get)
    return ran, skipped, seconds


def _result(future, case):
    """A task's result; its error stops the study, as one line unless it is rimcl's own."""
    try:
        return future.result()
    except RimclError:
        raise
    except Exception as exc:  # a task lost on too many workers (KilledWorker), cancelled...
        raise RimclError(f"a Dask task of case {case} failed: {type(exc).__name__}: {exc}") from exc


def shard_paths(out_dir, case, shards):
    """Files of every shard of one case, in tracer order."""
    return [shard_path(out_dir, case, shard) for shard in shards]


def _submit(client, plugin, study, stamp, out_dir, todo, shards):
    """One task per missing shard; a (threshold, shard)'s first task measures the reference.

    Returns
    -------
    futures : dict of Future to str
        Each task's case.
    waiting : dict of str to list
        The submitted tasks of each case of ``todo``.
    """
    run_id = uuid.uuid4().hex[:8]
    providers = {}  # (threshold, shard) -> (shard file with the reference, its task or None)
    futures, waiting = {}, {name: [] for name in todo}
    for name in study.names:
        config = study.measure(name)
        threshold = config.renderer.threshold
        for shard in shards:
            path = shard_path(out_dir, name, shard)
            provider = providers.get((threshold, shard))
            if name not in todo or path.exists():
                if path.exists() and provider is None:
                    providers[threshold, shard] = (path, None)
                continue
            reference_path, wait_for = (None, None) if provider is None else provider
            future = client.submit(
                measure_shard,
                plugin,
                config,
                stamp,
                name,
                shard,
                str(path),
                None if reference_path is None else str(reference_path),
                wait_for,
                key=f"rimcl-shard-{name}-{shard[0]}-{shard[1]}-{run_id}",
                pure=False,
            )
            if provider is None:
                providers[threshold, shard] = (path, future)
            futures[future] = name
            waiting[name].append(future)
    return futures, waiting
