"""Group commit for SQLite: one writer thread, the write jobs that arrive together in one
transaction (one fsync); each caller returns only after the commit holding its job
(:class:`crowdstudy.study.storage.StudyStore` uses it on SQLite, which allows one writer at a
time and pays an fsync per commit)."""

from __future__ import annotations

import threading

__all__ = ["GroupCommitWriter"]


class GroupCommitWriter:
    """One writer thread: write jobs that arrive together share one transaction and so one
    fsync; each caller returns only after the commit that contains its job. If a job
    raises, the batch rolls back and its jobs are re-run one transaction each, so one bad
    job never loses another's write."""

    _STOP = object()

    def __init__(self, engine, max_batch: int = 256):
        import queue

        self.engine, self.max_batch = engine, max_batch
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._loop, name="crowdstudy-db-writer", daemon=True)
        self.thread.start()

    def submit(self, job):
        """Run ``job(connection)`` in a committed transaction; return its result (or raise)."""
        import concurrent.futures

        if not self.thread.is_alive():
            raise RuntimeError("the database writer is closed")
        fut: concurrent.futures.Future = concurrent.futures.Future()
        self.queue.put((job, fut))
        return fut.result()

    def close(self) -> None:
        if self.thread.is_alive():
            self.queue.put(self._STOP)
            self.thread.join(timeout=10)

    def _run_one(self, item) -> None:
        job, fut = item
        try:
            with self.engine.begin() as conn:
                res = job(conn)
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting caller
            fut.set_exception(exc)
        else:
            fut.set_result(res)

    def _run_batch(self, batch) -> None:
        if len(batch) == 1:
            self._run_one(batch[0])
            return
        results = []
        try:
            with self.engine.begin() as conn:
                for job, _fut in batch:
                    results.append(job(conn))
        except Exception:  # noqa: BLE001 - isolate the failing job
            for item in batch:
                self._run_one(item)
            return
        for (_job, fut), res in zip(batch, results, strict=True):
            fut.set_result(res)

    def _loop(self) -> None:
        import queue

        while True:
            first = self.queue.get()
            if first is self._STOP:
                return
            batch, stop = [first], False
            while len(batch) < self.max_batch:
                try:
                    item = self.queue.get_nowait()
                except queue.Empty:
                    break
                if item is self._STOP:
                    stop = True
                    break
                batch.append(item)
            try:
                self._run_batch(batch)
            except BaseException as exc:  # noqa: BLE001 - never leave a caller waiting
                for _job, fut in batch:
                    if not fut.done():
                        fut.set_exception(exc)
            if stop:
                return
