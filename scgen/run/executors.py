"""Executors: run sample tasks on local worker processes or on a Ray cluster.

Each worker keeps one renderer alive across samples and writes its samples itself (every
sample's files are its own, written atomically), so executors only hand out tasks, collect
completions for the progress bar, and retry samples whose worker failed.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from scgen.errors import ScgenError
from scgen.io.parent_watch import spawn_pool
from scgen.run.worker import Done, SampleWorker, Task, WorkerSettings

MAX_ATTEMPTS = 3  # a sample is tried at most this often before the run stops
_worker: SampleWorker | None = None


def _init_process(settings: WorkerSettings) -> None:
    global _worker
    _worker = SampleWorker(settings)


def _run_in_process(task: Task) -> Done:
    assert _worker is not None
    return _worker.run(task)


def run_local(
    tasks: list[Task], settings: WorkerSettings, workers: int, on_done: Callable[[Done], None]
) -> None:
    """Run tasks on `workers` spawned processes; a crashed pool is rebuilt and its samples retried."""
    attempts = {t.index: 0 for t in tasks}
    pending = list(tasks)
    while pending:
        pool = spawn_pool(workers, _init_process, (settings,))
        try:
            pending = _drain(pool, pending, attempts, workers, on_done)
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _drain(pool: ProcessPoolExecutor, pending: list[Task], attempts: dict[int, int], workers: int,
           on_done: Callable[[Done], None]) -> list[Task]:  # fmt: skip
    """Feed the pool at most 2 tasks per worker at a time; returns tasks to retry after a crash."""
    queue = list(reversed(pending))
    running: dict[Future, Task] = {}
    while queue or running:
        while queue and len(running) < 2 * workers:
            try:
                fut = pool.submit(_run_in_process, queue[-1])
            except BrokenProcessPool:  # a worker died since the last wait: the pool takes nothing more
                return _after_crash(list(running.values()), queue, attempts)
            task = queue.pop()
            attempts[task.index] += 1
            running[fut] = task
        finished, _ = wait(running, return_when=FIRST_COMPLETED)
        for fut in finished:
            task = running.pop(fut)
            try:
                on_done(fut.result())
            except BrokenProcessPool:
                return _after_crash([task, *running.values()], queue, attempts)
            except Exception as exc:  # the renderer raised on this sample: retry it in place
                _check_attempts([task], attempts, f"{type(exc).__name__}: {exc}")
                queue.append(task)
    return []


def _after_crash(in_flight: list[Task], queue: list[Task], attempts: dict[int, int]) -> list[Task]:
    """A worker died (segfault, OOM kill): every in-flight and queued sample is retried in a new pool."""
    _check_attempts(in_flight, attempts, "its worker process died")
    return [*in_flight, *reversed(queue)]


def _check_attempts(tasks: Iterable[Task], attempts: dict[int, int], reason: str) -> None:
    for t in tasks:
        if attempts[t.index] >= MAX_ATTEMPTS:
            raise ScgenError(f"sample {t.index} failed {attempts[t.index]} times, stopping: {reason}")


def run_ray(
    tasks: list[Task], settings: WorkerSettings, workers: int, address: str | None, gpus_per_worker: float,
    on_done: Callable[[Done], None],
) -> None:  # fmt: skip
    """Run tasks on Ray actors (one persistent renderer each) writing to the shared output path."""
    try:
        import ray
        from ray.util.actor_pool import ActorPool
    except ImportError as exc:
        raise ScgenError("the ray executor needs Ray: pip install 'scgen[ray]'") from exc
    started = not ray.is_initialized()
    if started:
        ray.init(address=address, num_cpus=None if address else workers, log_to_driver=False)
    try:
        actor_cls = ray.remote(num_cpus=1, num_gpus=gpus_per_worker, max_restarts=MAX_ATTEMPTS)(SampleWorker)
        actors = [actor_cls.remote(settings) for _ in range(workers)]
        pool = ActorPool(actors)
        attempts = {t.index: 0 for t in tasks}
        pending = list(tasks)
        while pending:
            retry: list[Task] = []
            for task, result in zip(pending, _ordered_map(pool, pending, attempts), strict=True):
                if isinstance(result, Done):
                    on_done(result)
                else:
                    _check_attempts([task], attempts, result)
                    retry.append(task)
            pending = retry
    finally:
        if started:
            ray.shutdown()


def _ordered_map(pool, tasks: list[Task], attempts: dict[int, int]):
    """Yield each task's Done, or the error text when its actor raised or died."""
    for t in tasks:
        attempts[t.index] += 1
        pool.submit(lambda actor, task: actor.run.remote(task), t)
    for _ in tasks:
        try:
            yield pool.get_next()
        except Exception as exc:  # RayTaskError / RayActorError
            yield f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
