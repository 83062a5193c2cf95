"""Which stored episodes a command reads from an output folder: those of the latest run, or every
stored episode of a named experiment, whichever runs drove its parts (``vlocbench run ...
--methods sift`` first, the rest later). The store keeps episodes of older definitions too (a
changed setting gives new keys); an experiment's plan names only its own."""

from __future__ import annotations

from pathlib import Path

from vlocbench.bench.experiment import ExperimentPlan, load_experiment, plan_from_stored
from vlocbench.bench.store import EpisodeRow, StoreError, read_episodes, read_latest_run

Experiment = ExperimentPlan | str | Path  # a plan, or the path of its YAML file


def stored_episodes(
    output_dir: str | Path, experiment: Experiment | None = None
) -> tuple[ExperimentPlan, list[EpisodeRow]]:
    """The plan and the stored episodes of the latest run in ``output_dir``, or of ``experiment``
    (all of it that is stored there, by key)."""
    if experiment is None:
        stored, rows = read_latest_run(output_dir)
        return plan_from_stored(stored), rows
    plan = experiment if isinstance(experiment, ExperimentPlan) else load_experiment(experiment)
    keys = plan.cells_by_key  # every episode key of the plan, computed once
    rows = [r for r in read_episodes(output_dir) if r.key in keys]
    if not rows:
        raise StoreError(f"{output_dir} holds no episode of experiment {plan.name!r}")
    return plan, rows


def stored_rows(output_dir: str | Path, experiment: Experiment | None = None) -> list[EpisodeRow]:
    """The episodes of :func:`stored_episodes` alone (the latest run's without resolving its
    plan)."""
    if experiment is None:
        return read_latest_run(output_dir)[1]
    return stored_episodes(output_dir, experiment)[1]
