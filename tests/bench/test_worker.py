from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.worker import jobs_of

SPEC = {
    "name": "jobs",
    "towns": ["town10"],
    "methods": [
        "sift",
        {
            "name": "sift-gated",
            "features": "sift",
            "matcher": "nn-ratio",
            "retrieval": "vlad",
            "localizer": {"min_inliers": 12},
        },
    ],
    "sweep": {"illumination.k": [0, 6]},
    "repetitions": 2,
    "baseline_repetitions": 2,
}


def test_recall_episodes_of_one_setup_make_one_job():
    tasks = load_experiment(SPEC).tasks()  # 2 setups x 2 methods x (recall + 2 failures) + 2
    jobs = jobs_of(tasks)
    shared = [job for job in jobs if len(job) > 1]
    assert len(tasks) == 14 and len(jobs) == 12 and len(shared) == 2
    for job in shared:
        assert {t.kind for t in job} == {"recall"}
        assert {t.method_name for t in job} == {"sift", "sift-gated"}
        assert len({t.setup.label for t in job}) == 1
    assert sorted(t.key for job in jobs for t in job) == sorted(t.key for t in tasks)
    assert all(len(job) == 1 for job in jobs_of(tasks, share_drives=False))
    # a measured latency moves each method's localization ticks: nothing to share
    measured = load_experiment({**SPEC, "episode": {"latency": {"mode": "measured"}}}).tasks()
    assert all(len(job) == 1 for job in jobs_of(measured))
