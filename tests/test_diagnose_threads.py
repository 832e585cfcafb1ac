"""A diagnosis runs BLAS on one thread and gives the process its threads back
(``servo.diagnose.job.BLAS_THREADS``; docs/diagnosis-speed.md, section 12)."""
from threadpoolctl import threadpool_info, threadpool_limits

from servo.diagnose import job


def _blas_threads() -> list:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_blas_is_held_to_one_thread_during_a_diagnosis_and_restored_after(monkeypatch):
    seen = []
    monkeypatch.setattr(job, "_diagnose", lambda rec, opt: seen.append(_blas_threads()) or "diagnosis")
    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        assert before  # numpy's BLAS is found, so the check below is not empty
        assert job.diagnose(None) == "diagnosis"
        assert _blas_threads() == before
    assert seen and all(n == job.BLAS_THREADS for n in seen[0])
