"""The add-on's background jobs (a render, an optimisation) and what stops them.

A job runs limn on a worker thread that never touches bpy. Every native call it makes gets the
job's `keep_going` as its progress callback, so a cancel stops the C++ work within one 16 x 16
tile (limn raises RenderCancelled); between calls the worker checks the same flag.

No job may outlive what it depends on. They are cancelled and joined (waited for) here:
- when Blender closes the modal operator: on quit (WM_exit removes the window's modal handlers
  and calls the operator's cancel()), on File > New / Open / Revert and on closing the window;
- on bpy.app.handlers.load_pre (any file load, also from scripts);
- when the add-on is disabled (unregister);
- at Python's exit (atexit), the last moment before the interpreter is finalised: a worker
  still running then would be killed while it holds C++ frames (Python 3.11 ends such threads
  with a forced unwind, which limn's callback catches: "FATAL: exception not rethrown", abort)
  or would come back into a finalised interpreter (segmentation fault).
Neither Blender 3.4 nor 4.5 has a quit handler in bpy.app.handlers. Quitting Blender 3.4 in a
window with a job running reaches the add-on, in this order, through the operator's cancel(),
unregister() (WM_exit runs addon_utils.disable_all()) and atexit; each alone gives a clean exit
(checked in a window: tests/blender/window). The bpy module (4.5) reaches it through atexit.

One job per datablock at a time: a job names the datablocks it writes (`keys`), and
`busy(keys)` tells whether a running job holds one of them."""
from __future__ import annotations

import atexit
import threading
import time

_lock = threading.Lock()
_jobs: list["Job"] = []   # started and not yet forgotten (forget() after the main thread saw the end)


def log(message: str) -> None:
    """Messages that must reach the console (and the tests) even when no operator can report."""
    print(message, flush=True)


class Job:
    """A worker thread with a stop flag. Subclasses implement `work()` (on the worker thread) and
    describe themselves with `label` ("render into image 'x'", "optimisation of 'ball'")."""

    label = "limn job"

    def __init__(self, keys=()):
        self.keys = frozenset(keys)
        self._stop = threading.Event()
        self.stop_reason = ""          # why it was cancelled ("" while not cancelled)
        self.discard = False           # cancelled with nothing more to be written into Blender
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self.status_text = ""          # for the panel, set on the main thread
        self.release_ui = None         # undoes the modal operator's timer, progress and header text
        self.announced = False         # its stop was printed

    # ---- worker side ---------------------------------------------------------------------------
    def keep_going(self, *_args) -> bool:
        """The progress callback of the native calls: False cancels (limn raises RenderCancelled)."""
        return not self._stop.is_set()

    def work(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _run(self) -> None:
        try:
            self.work()
        except BaseException as e:  # reported on the main thread; RenderCancelled when cancelled
            self.error = e

    # ---- main thread -----------------------------------------------------------------------------
    def start(self) -> None:
        with _lock:
            other = _holder(self.keys)
            if other is not None:
                raise JobBusy(other)
            _jobs.append(self)
        self._thread = threading.Thread(target=self._run, daemon=True, name=f"limn: {self.label}")
        self._thread.start()

    @property
    def cancelled(self) -> bool:
        return self._stop.is_set()

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def cancel(self, reason: str = "cancelled", discard: bool = False) -> None:
        """Asks the worker to stop (keeps the first reason given). discard=True: write nothing more
        into Blender (what the job would write into is going away: file load, undo, quit)."""
        self.discard = self.discard or discard
        if not self._stop.is_set():
            self.stop_reason = reason
            self._stop.set()

    def join(self, timeout: float | None = None) -> bool:
        """Waits for the worker (releasing the GIL); True when it has ended."""
        if self._thread is not None:
            self._thread.join(timeout)
        return not self.alive

    def stop(self, reason: str, timeout: float | None = None, discard: bool = False) -> float:
        """cancel() and join(); returns the seconds it took."""
        t0 = time.perf_counter()
        self.cancel(reason, discard)
        self.join(timeout)
        return time.perf_counter() - t0

    def announce(self) -> None:
        """Prints that the job stopped and why (once)."""
        if not self.announced:
            self.announced = True
            log(f"limn: {self.label} stopped: {self.stop_reason}")

    def forget(self) -> None:
        """Drops the job from the registry (its keys become free); call after the end was handled."""
        with _lock:
            if self in _jobs:
                _jobs.remove(self)


class JobBusy(ValueError):
    def __init__(self, job: Job):
        self.job = job
        super().__init__(f"limn: {job.label} is running{f' ({job.status_text})' if job.status_text else ''}; "
                         "press Esc (or Stop in the limn panel) to end it first")


def _holder(keys) -> Job | None:
    return next((j for j in _jobs if j.keys & frozenset(keys)), None)


def busy(keys) -> Job | None:
    """The running (not yet forgotten) job that holds one of `keys`, or None."""
    with _lock:
        return _holder(keys)


def running() -> list[Job]:
    with _lock:
        return list(_jobs)


def stop_all(reason: str, timeout: float | None = None, kinds: tuple[type, ...] = (Job,)) -> list[Job]:
    """Cancels every running job (of the given classes) with nothing more to write (discard) and
    waits for them; prints what it stopped. Returns the jobs that were running."""
    jobs = [j for j in running() if isinstance(j, kinds) and j.alive]
    if not jobs:
        return []
    t0 = time.perf_counter()
    for j in jobs:
        j.cancel(reason, discard=True)
    for j in jobs:
        j.join(timeout)
        if not j.alive:
            j.announce()
    still = [j.label for j in jobs if j.alive]
    log(f"limn: stopped {len(jobs) - len(still)} job(s) in {time.perf_counter() - t0:.2f} s ({reason})" +
        (f"; still running after {timeout} s: {', '.join(still)}" if still else ""))
    return jobs


def _at_exit() -> None:
    stop_all("Python is shutting down (Blender quits)")
    for j in running():  # nothing polls any more
        j.forget()


_registered = False


def register() -> None:
    global _registered
    if not _registered:
        atexit.register(_at_exit)
        _registered = True


def unregister() -> None:
    """Stops every job (the add-on is being disabled); keeps the atexit hook while jobs remain."""
    global _registered
    stop_all("the limn add-on is being disabled")
    for j in running():
        j.forget()
        if j.release_ui is not None:  # Blender drops the modal operators of unregistered classes
            j.release_ui()
            j.release_ui = None
    if _registered:
        atexit.unregister(_at_exit)
        _registered = False
