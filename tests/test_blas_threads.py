"""One BLAS thread for small dense linear algebra (cfbmarkov._blas): one limit shared by
nested and concurrent users, taken by the first in and lifted by the last out, whatever
order the threads leave in (a thread leaving must not lift it under another)."""

import threading

import cfbmarkov._blas as blas


class RecordingController:
    """Stands in for threadpoolctl's controller: records the limits set and lifted."""

    def __init__(self):
        self.events = []

    def limit(self, limits, user_api):
        self.events.append(("limit", limits, user_api))
        controller = self

        class Limiter:
            def restore_original_limits(self):
                controller.events.append(("restore",))

        return Limiter()


def test_the_limit_is_lifted_by_the_last_thread_out(monkeypatch):
    recorder = RecordingController()
    monkeypatch.setattr(blas, "_controller", recorder)
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def first():
        with blas.one_blas_thread():
            first_in.set()
            second_in.wait(10)
        first_out.set()

    def second():
        first_in.wait(10)
        with blas.one_blas_thread():
            second_in.set()
            first_out.wait(10)
            seen["after the first left"] = list(recorder.events)

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert seen["after the first left"] == [("limit", 1, "blas")]      # still limited
    assert recorder.events == [("limit", 1, "blas"), ("restore",)]     # lifted once, last
    recorder.events.clear()
    with blas.one_blas_thread():
        with blas.one_blas_thread():
            pass
        assert recorder.events == [("limit", 1, "blas")]
    assert recorder.events == [("limit", 1, "blas"), ("restore",)]


def test_an_exception_inside_still_lifts_the_limit(monkeypatch):
    recorder = RecordingController()
    monkeypatch.setattr(blas, "_controller", recorder)
    try:
        with blas.one_blas_thread():
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass
    assert recorder.events[-1] == ("restore",) and blas._inside == 0
