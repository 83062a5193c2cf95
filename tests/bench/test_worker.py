import dataclasses

from vlocbench.bench.episode import LatencyConfig
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.worker import jobs_of


def test_recall_episodes_of_one_setup_make_one_job():
    # the demo: 5 setups x 2 methods (sift, sift-gated) x (recall + 2 failures) + 10 odometry
    plan = load_experiment("experiments/demo.yaml")
    tasks = plan.tasks()
    jobs = jobs_of(tasks)
    shared = [job for job in jobs if len(job) > 1]
    assert len(tasks) == 40 and len(jobs) == 35 and len(shared) == 5
    for job in shared:
        assert {t.kind for t in job} == {"recall"}
        assert {t.method_name for t in job} == {"sift", "sift-gated"}
        assert len({t.setup.label for t in job}) == 1
    assert sorted(t.key for job in jobs for t in job) == sorted(t.key for t in tasks)
    assert all(len(job) == 1 for job in jobs_of(tasks, share_drives=False))
    # a measured latency moves each method's localization ticks: nothing to share
    measured = [
        dataclasses.replace(
            t, episode=dataclasses.replace(t.episode, latency=LatencyConfig("measured"))
        )
        for t in tasks
    ]
    assert all(len(job) == 1 for job in jobs_of(measured))
