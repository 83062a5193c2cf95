"""The ``vlocbench`` command line. The only place that turns errors into messages and exit codes
(listed in ``vlocbench --help``)."""

from __future__ import annotations

import _thread
import argparse
import contextlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vlocbench import __version__
from vlocbench.config import NATIVE_LOG_ENV
from vlocbench.errors import VlocbenchError

if TYPE_CHECKING:
    from vlocbench.bench.visual import VisualLocalizer

EXIT_INPUT = 1
EXIT_USAGE = 2  # argparse's own
EXIT_MACHINE = 3
EXIT_INTERRUPTED = 130  # the shell's code for a SIGINT


def _towns(args: argparse.Namespace) -> int:
    from vlocbench.sim.birdseye import save_town_map
    from vlocbench.sim.generation import TownSet
    from vlocbench.sim.town import builtin_town_names, generate_town, load_town_spec

    names = builtin_town_names()
    if args.generate:
        names = TownSet(args.generate, args.style, args.seed).names()
        args.output.mkdir(parents=True, exist_ok=True)
    for name in names:
        town = generate_town(load_town_spec(name))
        print(
            f"{name}: {town.spec.style}, {len(town.buildings)} buildings, route "
            f"{town.route.length_m:.0f} m with {town.route.num_turns} turns"
        )
        if args.generate:
            save_town_map(town, args.output / f"{name}.png")
    if args.generate:
        print(f"wrote {len(names)} maps to {args.output}")
    return 0


def _map(args: argparse.Namespace) -> int:
    from vlocbench.sim.birdseye import save_town_map
    from vlocbench.sim.town import generate_town, load_town_spec

    town = generate_town(load_town_spec(args.town))
    out = args.output or Path(f"{town.name}.png")
    save_town_map(town, out, route=not args.no_route)
    print(f"wrote {out}")
    return 0


def _render(args: argparse.Namespace) -> int:
    import cv2

    from vlocbench.sim import (
        Camera,
        Conditions,
        Extrinsics,
        Headlights,
        Illumination,
        Intrinsics,
        Simulator,
        StreetLights,
        Viewpoint,
        Weather,
    )
    from vlocbench.sim.town import generate_town, load_town_spec

    town = generate_town(load_town_spec(args.town))
    conditions = Conditions(
        illumination=Illumination(k=args.k),
        weather=Weather(
            fog_visual_range_m=args.fog,
            rain=args.rain,
            overcast=args.overcast,
            deposits=args.deposits,
        ),
        season=args.season,
        viewpoint=Viewpoint(args.dz, args.pitch_down),
        headlights=Headlights(on=args.headlights),
        street_lights=StreetLights(args.street_lights),
        shadows=args.shadows,
    )
    camera = Camera(
        "cli",
        Intrinsics(args.width, args.height, args.fov),
        Extrinsics(yaw_deg=args.yaw),
        antialias=args.antialias,
    )
    n = len(town.route.waypoints_xy)
    if not 0 <= args.waypoint < n:
        raise VlocbenchError(f"--waypoint: must be in [0, {n - 1}] for {town.name}'s route")
    x, y = town.route.waypoints_xy[args.waypoint]
    with Simulator(town, conditions) as sim:
        sim.teleport(float(x), float(y), float(town.route.yaw_rad[args.waypoint]))
        frame = sim.render([camera])[0]
    cv2.imwrite(str(args.output), frame.image[:, :, ::-1])
    print(f"wrote {args.output}")
    return 0


def _tour(args: argparse.Namespace) -> int:
    from vlocbench.sim.tour import run_tour

    index = run_tour(args.out, towns=args.towns, stops=args.stops)
    print(f"report: {index.resolve()}")
    return 0


def _visual_localizer(map_dir: Path | None) -> VisualLocalizer:
    """The map's localizer on a camera like the one that took its gallery (right-facing mount)."""
    import json

    from vlocbench.bench.visual import VisualLocalizer
    from vlocbench.loc.gallery import Gallery
    from vlocbench.sim import Camera, Extrinsics, Intrinsics

    if map_dir is None:
        raise VlocbenchError("--localizer visual needs --map MAP_DIR (see `vlocbench build-map`)")
    info = map_dir / "map.json"
    if not info.is_file():
        raise VlocbenchError(f"--map: {map_dir} is not a map (no map.json)")
    gallery = Gallery.load(json.loads(info.read_text())["gallery"])
    model = next(iter(gallery.cameras.values()))
    camera = Camera("gallery", Intrinsics(model.width, model.height, model.fov_deg), Extrinsics())
    return VisualLocalizer(map_dir, (camera,))


def _drive(args: argparse.Namespace) -> int:
    import dataclasses

    import numpy as np

    from vlocbench.bench import (
        EpisodeConfig,
        OracleConfig,
        OracleLocalizer,
        plan_town_route,
        run_episode,
    )
    from vlocbench.bench.localizer import Localizer
    from vlocbench.config import config_hash, from_dict, load_yaml
    from vlocbench.errors import UnknownNameError
    from vlocbench.sim import Simulator
    from vlocbench.sim.town import generate_town, load_town_spec

    localizers: dict[str, Callable[[], Localizer | None]] = {
        "odometry": lambda: None,
        "oracle": lambda: OracleLocalizer(OracleConfig(args.oracle_sigma, args.oracle_yaw_deg)),
        "visual": lambda: _visual_localizer(args.map),
    }
    if args.localizer not in localizers:
        raise UnknownNameError("localizer", args.localizer, localizers)
    base = from_dict(EpisodeConfig, load_yaml(args.config)) if args.config else EpisodeConfig()
    if args.mode:
        base = dataclasses.replace(base, mode=args.mode)
    town = generate_town(load_town_spec(args.town))
    path = plan_town_route(town)
    localizer = localizers[args.localizer]()
    print(
        f"{town.name}: route {path.length_m:.0f} m; {args.localizer}, {base.mode}; "
        f"config {config_hash(base)}"
    )
    rates, drives = [], {}
    with Simulator(town) as sim:
        for seed in range(args.seed, args.seed + args.seeds):
            r = run_episode(sim, path, localizer, dataclasses.replace(base, seed=seed))
            rates.append(r.failures_per_km)
            drives[f"seed {seed}"] = r
            causes = ", ".join(f"{x.cause} at {x.resume_s_m:.0f} m" for x in r.reinitializations)
            print(
                f"  seed {seed}: {r.failures} failures ({r.failures_per_km:.1f}/km), tracking "
                f"{r.tracking_error_mean_m:.2f} m, {'done' if r.completed else 'TIMED OUT'} in "
                f"{r.sim_time_s:.0f} s simulated ({r.real_time_factor:.0f}x real time)"
                + (f"; {causes}" if causes else "")
            )
    print(f"failure rate F = {np.mean(rates):.1f} per km over {len(rates)} episodes")
    if args.plot:
        from vlocbench.bench.plots import save_episode_map

        print(f"wrote {save_episode_map(town, drives, args.plot)}")
    return 0


def _run(args: argparse.Namespace) -> int:
    from vlocbench.bench.experiment import load_experiment
    from vlocbench.bench.report import summary_lines, write_report
    from vlocbench.bench.runner import run_experiment
    from vlocbench.bench.worker import default_workers

    plan = load_experiment(args.experiment).only(
        args.towns or (), args.methods or (), args.kinds or (), args.setup or (), args.repetitions
    )
    if args.output:
        plan = plan.with_output(args.output)
    workers = args.workers or default_workers()
    if args.dry_run:
        from vlocbench.bench.forecast import forecast

        print("\n".join(forecast(plan, args.reuse or ()).lines(workers)))
        return 0
    summary = run_experiment(
        plan,
        workers=workers,
        scheduler=args.scheduler,
        progress=not args.no_progress,
        reuse=args.reuse or (),
    )
    overhead = summary.harness_overhead
    reused = f" ({summary.reused} of them taken from other stores)" if args.reuse else ""
    print(
        f"{plan.name}: {summary.finished} episodes run, {summary.skipped} done before{reused}, "
        f"{summary.errors} with errors; {summary.workers_lost} workers died, "
        f"{summary.retried} episodes rerun after it; {summary.wall_s / 60:.1f} min "
        + (
            f"(harness overhead {100 * overhead:.1f} %)"
            if overhead is not None
            else "(no harness overhead: a worker died)"
        )
    )
    if args.no_report:
        return 1 if summary.errors else 0
    files = write_report(plan.output_dir, examples=not args.no_examples)
    print("\n".join(summary_lines(files.summary)))
    if files.platforms:
        print(files.platforms)
    print(f"report: {files.html.resolve()}")
    if args.towns or args.methods or args.kinds or args.setup or args.repetitions:
        print(
            f"(of this part; of the whole experiment: vlocbench report {plan.output_dir} "
            f"--experiment {args.experiment})"
        )
    return 1 if summary.errors else 0


def _missing_ros_extra(exc: ImportError) -> VlocbenchError:
    from vlocbench.errors import MachineError

    return MachineError(f"the ros extra is not installed ({exc}): pip install 'vlocbench[ros]'")


def _view(args: argparse.Namespace) -> int:
    from vlocbench.bench.view import VIEW_DIR, choose_episode, record_episode

    row = choose_episode(
        args.output,
        args.episode,
        args.setup,
        args.method,
        args.experiment,
        town=args.town,
        kind=args.kind,
        repetition=args.repetition,
        failed=args.failed,
    )
    out = args.out or args.output / VIEW_DIR / f"{row.key}.rrd"
    record_episode(args.output, row, out, images=args.images, spawn=args.spawn)
    print(
        f"wrote {out} ({row.kind} drive, {row.town}, {row.method or 'odometry only'}, "
        f"{row.setup}, repetition {row.repetition}): open it with `rerun {out}`"
    )
    return 0


def _export(args: argparse.Namespace) -> int:
    if args.format:
        from vlocbench.bench.export import EXPORT_DIR, export_run

        written = export_run(args.output, args.format, args.experiment)
        print(f"wrote {len(written)} files to {args.output / EXPORT_DIR / args.format}")
        return 0
    try:
        from vlocbench.ros.bags import export_bags
    except ImportError as exc:
        raise _missing_ros_extra(exc) from None
    written = export_bags(args.output, images=args.images, experiment=args.experiment)
    print(f"wrote {len(written)} bags to {args.output / 'bags'}")
    return 0


@contextlib.contextmanager
def _signals_interrupt() -> Iterator[None]:
    """SIGTERM, and SIGINT even where a shell started the command in the background with it
    ignored, interrupt it as Ctrl-C does: a run's workers stop, the store and the caches keep what
    they have (a gallery or a map is written last, so an interrupted one is made again).

    A signal whose handler ran inside a finalizer (a weakref callback or ``__del__`` run by the
    garbage collector) has its KeyboardInterrupt swallowed by Python, which passes it to
    ``sys.unraisablehook``; the hook has a thread send the signal again once the hook has
    returned (sent at once, it would be handled inside the hook and swallowed again), so it lands
    in ordinary code."""
    stopping = {signal.Signals(sig).name: sig for sig in (signal.SIGINT, signal.SIGTERM)}

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)

    previous_hook = sys.unraisablehook

    def resend_swallowed(unraisable: Any) -> None:
        exc = unraisable.exc_value
        if isinstance(exc, KeyboardInterrupt) and exc.args and exc.args[0] in stopping:
            resend = threading.Timer(0.01, _thread.interrupt_main, (stopping[exc.args[0]],))
            resend.daemon = True
            resend.start()
        else:
            previous_hook(unraisable)

    old = {sig: signal.signal(sig, interrupt) for sig in stopping.values()}
    sys.unraisablehook = resend_swallowed
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        for sig, handler in old.items():
            signal.signal(sig, handler)


def _platform(args: argparse.Namespace) -> int:
    import json

    from vlocbench.bench.platform import current_platform
    from vlocbench.bench.store import count_platforms, read_platforms

    here = current_platform()
    mine = here.to_dict()
    if args.json:
        print(json.dumps(mine, indent=1))
    else:
        d = here.details
        print(f"platform {here.id}")
        print(
            f"  render   {here.render}  {d['gl_renderer']}, {d['gl_version']} ({d['gl_backend']})"
        )
        print(f"  numeric  {here.numeric}  {d['cpu']}, Python {d['python']}")
        torch = here.torch or "-" * 16
        print(
            f"  torch    {torch}  {d.get('torch_device') or d.get('torch_error', 'not installed')}"
        )
        print("  packages " + ", ".join(f"{k} {v or '-'}" for k, v in here.packages.items()))
    for output in args.output:
        counts = count_platforms(output)
        records = read_platforms(output)
        print(f"{output}: {sum(counts.values())} finished episodes")
        for platform_id, n in sorted(counts.items(), key=lambda x: (x[0] is None, -x[1])):
            if platform_id is None:
                print(f"  {n:6d} stored before platforms were recorded")
                continue
            other = records.get(platform_id, {})
            differs = [
                k for k in ("render", "numeric", "torch", "packages") if other.get(k) != mine[k]
            ]
            how = "this machine's" if platform_id == here.id else f"not this machine's: {differs}"
            print(f"  {n:6d} on {platform_id} ({how})")
    return 0


def _verify(args: argparse.Namespace) -> int:
    from vlocbench.bench.verify import verify_episodes

    verdicts = verify_episodes(
        args.output,
        args.experiment,
        args.count,
        args.kinds or (),
        args.key or (),
        args.seed,
        args.methods or (),
    )
    for v in verdicts:
        print(v.line())
    impure = [v for v in verdicts if v.same is False and v.same_platform]
    elsewhere = [v for v in verdicts if v.same is False and not v.same_platform]
    same = sum(v.same is True for v in verdicts)
    print(
        f"{same} of {len(verdicts)} the same to the last digit"
        + (f"; {len(impure)} differ on the platform they were stored on" if impure else "")
        + (f"; {len(elsewhere)} differ, stored on another platform" if elsewhere else "")
    )
    return 1 if impure else 0


def _report(args: argparse.Namespace) -> int:
    from vlocbench.bench.report import not_stored_line, summary_lines, write_report
    from vlocbench.bench.store import count_episodes

    files = write_report(args.output, examples=not args.no_examples, plan=args.experiment)
    print("\n".join(summary_lines(files.summary)))  # as a run ends: each town's F table
    print(
        f"{files.summary.episodes} of the {files.summary.planned} episodes of {files.summary.plan.name}"
    )
    for line in (not_stored_line(files.summary), files.platforms):
        if line:
            print(line)
    if args.experiment:
        # after a changed setting or definition (new keys) the older episodes stay in the store
        others = count_episodes(args.output) - files.summary.episodes
        if others:
            print(
                f"{others} more episodes in {args.output} are of other settings or earlier "
                "definitions (not in this report)"
            )
    print(f"tables: {files.markdown}, {files.latex}")
    print(f"report: {files.html.resolve()}")
    return 0


def _cache(args: argparse.Namespace) -> int:
    import time

    from vlocbench.bench import cache
    from vlocbench.bench.experiment import load_experiment

    if args.delete and not args.keep:
        raise VlocbenchError(
            "--delete: name the experiments whose galleries and maps to keep (--keep)"
        )
    if not args.cache.is_dir():
        raise VlocbenchError(f"--cache: {args.cache} is not a folder")
    found = cache.entries(args.cache)
    plans = [load_experiment(path) for path in args.keep or ()]
    stale = {e.path for e in cache.unused(args.cache, plans, found)} if plans else set()
    for e in found:
        changed = time.strftime("%Y-%m-%d", time.localtime(e.modified_s))
        mark = "  unused" if e.path in stale else ""
        made_on = e.platform or "-" * 12  # the platform that made it (vlocbench platform)
        print(f"{e.size_bytes / 1e6:9.0f} MB  {changed}  {made_on}  {e.name}{mark}")
    total = sum(e.size_bytes for e in found)
    print(
        f"{args.cache}: {sum(e.kind == 'gallery' for e in found)} galleries, "
        f"{sum(e.kind == 'map' for e in found)} maps, {total / 1e9:.2f} GB"
    )
    if plans:
        freed = [e for e in found if e.path in stale]
        print(
            f"{len(freed)} of them ({sum(e.size_bytes for e in freed) / 1e9:.2f} GB) used by none "
            f"of the {len(plans)} experiment(s)"
            + ("" if args.delete else "; --delete removes them")
        )
        if args.delete:
            busy = [e.name for e in freed if not cache.delete(e)]
            print(
                f"deleted {len(freed) - len(busy)}"
                + (f"; being built, kept: {', '.join(busy)}" if busy else "")
            )
    return 0


def _gallery(args: argparse.Namespace) -> int:
    from vlocbench.bench.gallery_capture import capture_gallery
    from vlocbench.bench.towns import plan_town_route
    from vlocbench.sim import Camera, Conditions, Extrinsics, Illumination, Intrinsics, Simulator
    from vlocbench.sim.town import generate_town, load_town_spec

    town = generate_town(load_town_spec(args.town))
    camera = Camera(
        "gallery", Intrinsics(args.width, args.height, args.fov), Extrinsics(), args.antialias
    )
    out = args.out or Path("galleries") / f"{town.name}-k{args.k:g}"
    with Simulator(town, Conditions(illumination=Illumination(k=args.k))) as sim:
        gallery = capture_gallery(
            sim, plan_town_route(town), (camera,), out, spacing_m=args.spacing, speed_mps=args.speed
        )
    print(f"wrote {len(gallery)} images with their poses to {out}")
    return 0


def _gallery_import(args: argparse.Namespace) -> int:
    from vlocbench.loc.mapping import import_colmap

    gallery = import_colmap(args.model, args.images, args.out)
    print(f"wrote a gallery of {len(gallery)} images with their poses to {args.out}")
    return 0


def _gallery_export(args: argparse.Namespace) -> int:
    from vlocbench.loc.gallery import Gallery
    from vlocbench.loc.mapping import export_colmap

    gallery = Gallery.load(args.gallery)
    export_colmap(gallery, args.out)
    print(
        f"wrote the COLMAP model of {len(gallery)} images to {args.out} "
        f"(images in {gallery.root / 'images'})"
    )
    return 0


def _build_map(args: argparse.Namespace) -> int:
    from vlocbench.loc.gallery import Gallery
    from vlocbench.loc.mapping import (
        MappingConfig,
        MatchPool,
        build_map,
        default_map_dir,
        pools_matching,
    )
    from vlocbench.loc.registry import method_conf

    gallery = Gallery.load(args.gallery)
    conf = method_conf(args.method)
    mapping = MappingConfig(
        pairs=args.pairs,
        num_pairs=args.num_pairs,
        verification=args.verification,
        min_track_length=args.min_track_length,
    )
    out = args.out or default_map_dir("maps", gallery, conf, mapping)

    def progress(stage: str, done: int, total: int) -> None:
        if done == total or done % 50 == 0:
            print(f"  {stage}: {done}/{total}", flush=True)

    if args.workers > 1 and pools_matching(conf):
        from vlocbench.bench.executors import worker_pool  # the simulator's and a run's imports

        with worker_pool(args.workers) as pool:
            match_pool = MatchPool(pool, args.workers)
            report = build_map(gallery, conf, out, mapping, args.overwrite, progress, match_pool)
    else:  # SIFT's nearest neighbours: fast, on every core through BLAS already
        report = build_map(gallery, conf, out, mapping, overwrite=args.overwrite, progress=progress)
    times = ", ".join(f"{k} {v:.0f} s" for k, v in report.seconds.items())
    print(
        f"map {out}: {report.images} images, {report.pairs} pairs, {report.points} points, "
        f"mean track length {report.mean_track_length:.2f}, mean reprojection error "
        f"{report.mean_reprojection_error_px:.2f} px ({times})"
    )
    return 0


def _train_retrieval(args: argparse.Namespace) -> int:
    import dataclasses

    from vlocbench.bench.experiment import load_experiment
    from vlocbench.bench.retrieval_training import (
        RetrievalTraining,
        TrainingSet,
        conditions_from,
        render_record,
        render_training_set,
        train_netvlad,
    )
    from vlocbench.loc.netvlad import save_weights

    spec = RetrievalTraining(seed=args.seed, **({"epochs": args.epochs} if args.epochs else {}))
    towns = load_experiment(args.towns)
    setups = conditions_from(args.conditions)
    if args.data and args.data.is_file():
        data = TrainingSet.load(str(args.data))
        data.require_rendered_from(render_record(towns, setups, spec), str(args.data))
    else:
        data = render_training_set(towns, setups, spec, progress=print)
        if args.data:
            data.save(str(args.data))
    params, report = train_netvlad(data, spec, progress=print)
    meta = {
        "spec": dataclasses.asdict(spec),
        "rendered_with": data.rendered_with,
        "towns": list(data.towns),
        "setups": list(data.setups),
        "gallery_images": len(data.gallery_xy),
        "queries": len(data.query_xy),
        "loss": report.loss,
        "held_out_recall": report.recall,
        "held_out_recall_by_setup": report.recall_by_setup,
        "backbone": "efficientnet-lite0 (ImageNet), frozen",
    }
    digest = save_weights(args.output, params, meta)
    print(f"{args.output}: digest {digest}, trained in {report.seconds:.0f} s")
    return 0


def _localize(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from vlocbench.errors import LocalizationError
    from vlocbench.loc.features import check_image
    from vlocbench.loc.gallery import Gallery
    from vlocbench.loc.localizer import MapLocalizer

    localizer = MapLocalizer(args.map)
    gallery = Gallery.load(localizer.gallery_dir)
    camera_name = args.camera or next(iter(gallery.cameras))
    if camera_name not in gallery.cameras:
        raise LocalizationError(
            f"--camera: {camera_name!r} is not one of {sorted(gallery.cameras)}"
        )
    bgr = cv2.imread(str(args.image), cv2.IMREAD_COLOR)
    if bgr is None:
        raise LocalizationError(f"{args.image} is missing or not an image")
    prior = None
    if args.prior_image:
        if args.prior_image not in gallery.names:
            raise LocalizationError(f"--prior-image: {args.prior_image!r} is not in the gallery")
        prior = gallery.images[gallery.index_of(args.prior_image)].world_from_cam
    image = check_image(bgr[:, :, ::-1], str(args.image))
    result = localizer.localize(image, gallery.cameras[camera_name], prior)
    times = ", ".join(f"{k} {1000 * v:.0f} ms" for k, v in result.seconds.items())
    if not result.success:
        print(f"failed: {result.reason} (retrieved {', '.join(result.retrieved)}; {times})")
        return 1
    assert result.world_from_cam is not None
    with np.printoptions(precision=4, suppress=True):
        print(f"world_from_cam =\n{result.world_from_cam}")
    print(
        f"{result.num_inliers} inliers of {result.num_correspondences} correspondences; "
        f"cluster {', '.join(result.cluster)}; {times}"
    )
    return 0


def _names(text: str) -> tuple[str, ...]:
    """An argparse type: comma-separated names, at least one."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise argparse.ArgumentTypeError("expected comma-separated names, got none")
    return names


def _whole_number(text: str, least: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < least:
        raise argparse.ArgumentTypeError(f"must be at least {least}, got {value}")
    return value


def _count(text: str) -> int:
    """An argparse type: a whole number >= 1."""
    return _whole_number(text, 1)


def _index(text: str) -> int:
    """An argparse type: a whole number >= 0."""
    return _whole_number(text, 0)


def _parents() -> dict[str, argparse.ArgumentParser]:
    """Options that several verbs share, defined once."""
    town = argparse.ArgumentParser(add_help=False)
    town.add_argument("town", help="built-in town name (see `vlocbench towns`) or a town spec YAML")
    camera = argparse.ArgumentParser(add_help=False)
    camera.add_argument("--width", type=_count, default=800, help="image width in pixels")
    camera.add_argument("--height", type=_count, default=600, help="image height in pixels")
    camera.add_argument(
        "--fov", type=float, default=90.0, help="horizontal field of view in degrees"
    )
    camera.add_argument(
        "--antialias",
        action="store_true",
        help="4 samples per pixel instead of 1 (about twice the render time)",
    )
    k = argparse.ArgumentParser(add_help=False)
    k.add_argument("--k", type=float, default=0.0, help="illumination level k, 0 (noon) to 10")
    report = argparse.ArgumentParser(add_help=False)
    report.add_argument(
        "--no-examples", action="store_true", help="report without example images (no rendering)"
    )
    return {"town": town, "camera": camera, "k": k, "report": report}


def _add_town_verbs(sub: Any, shared: dict[str, argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "towns",
        help="list the built-in towns and their routes, or generate towns and write their maps",
    )
    p.add_argument(
        "--generate",
        type=_count,
        metavar="COUNT",
        help="draw COUNT towns (named gen-STYLE-SEED-INDEX, usable wherever a town is named)",
    )
    p.add_argument("--style", default="town", help="style of generated towns: town or city")
    p.add_argument("--seed", type=int, default=0, help="seed of the generated set")
    p.add_argument(
        "-o", "--output", type=Path, default=Path("towns"), help="folder for generated towns' maps"
    )
    p.set_defaults(func=_towns)

    p = sub.add_parser(
        "map", parents=[shared["town"]], help="write a bird's-eye map of a town and its route (PNG)"
    )
    p.add_argument("-o", "--output", type=Path, help="PNG path (default: TOWN.png)")
    p.add_argument("--no-route", action="store_true", help="draw the town without its route")
    p.set_defaults(func=_map)

    p = sub.add_parser(
        "render",
        parents=[shared["town"], shared["camera"], shared["k"]],
        help="render one camera image at a route waypoint",
    )
    p.add_argument("-o", "--output", type=Path, default=Path("render.png"), help="image path")
    p.add_argument("--waypoint", type=int, default=0, help="route waypoint index (2 m apart)")
    p.add_argument("--fog", type=float, default=None, help="fog visual range in metres")
    p.add_argument("--rain", type=float, default=0.0, help="rain strength in [0, 1]")
    p.add_argument("--overcast", type=float, default=0.0, help="overcast in [0, 1]")
    p.add_argument(
        "--deposits",
        type=float,
        default=None,
        help="puddles on the road in [0, 1] (default: --rain)",
    )
    p.add_argument("--season", default="summer", help="summer, autumn or winter")
    p.add_argument("--headlights", action="store_true", help="switch the headlights on")
    p.add_argument(
        "--street-lights",
        default="auto",
        help="the town's lamps and windows: auto (on at night), on or off",
    )
    p.add_argument("--shadows", action="store_true", help="the sun casts shadows (slower)")
    p.add_argument("--dz", type=float, default=0.0, help="camera height offset in metres")
    p.add_argument("--pitch-down", type=float, default=0.0, help="camera tilt down in degrees")
    p.add_argument("--yaw", type=float, default=-90.0, help="camera yaw in degrees (-90: right)")
    p.set_defaults(func=_render)

    p = sub.add_parser("tour", help="render towns under every condition and write an HTML report")
    p.add_argument("--out", type=Path, default=Path("out/tour"), help="output folder")
    p.add_argument("--towns", nargs="+", default=["town01", "town10"], help="towns to use")
    p.add_argument("--stops", type=_count, default=3, help="places along each route to render")
    p.set_defaults(func=_tour)


def _add_drive_verb(sub: Any, shared: dict[str, argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "drive",
        parents=[shared["town"]],
        help="drive a town's route in closed loop and print failure rates",
    )
    p.add_argument(
        "--localizer", default="odometry", help="odometry (none), oracle, or visual (with --map)"
    )
    p.add_argument("--map", type=Path, help="map folder for --localizer visual")
    p.add_argument("--mode", choices=("navigate", "ground_truth"), help="override the config's")
    p.add_argument("--config", type=Path, help="episode config YAML (EpisodeConfig fields)")
    p.add_argument("--seed", type=int, default=0, help="first seed")
    p.add_argument("--seeds", type=_count, default=1, help="number of episodes (seeds), >= 1")
    p.add_argument("--oracle-sigma", type=float, default=0.1, help="oracle position noise, m")
    p.add_argument("--oracle-yaw-deg", type=float, default=1.0, help="oracle yaw noise, deg")
    p.add_argument(
        "--plot", type=Path, help="PNG of the drives on the town map (true and EKF paths, failures)"
    )
    p.set_defaults(func=_drive)


def _add_map_verbs(sub: Any, shared: dict[str, argparse.ArgumentParser]) -> None:
    p = sub.add_parser("gallery", help="galleries: capture one in a town, or take one from COLMAP")
    verbs = p.add_subparsers(dest="gallery_command", required=True, metavar="VERB")
    q = verbs.add_parser(
        "capture",
        parents=[shared["town"], shared["camera"], shared["k"]],
        help="drive a town's route and save gallery images with poses",
    )
    q.add_argument("--out", type=Path, help="gallery folder (default: galleries/TOWN-kK)")
    q.add_argument("--spacing", type=float, default=2.0, help="metres between images")
    q.add_argument("--speed", type=float, default=8.0, help="driving speed, m/s")
    q.set_defaults(func=_gallery)
    q = verbs.add_parser("import", help="a gallery from a COLMAP model with images (any posed set)")
    q.add_argument("model", type=Path, help="COLMAP model folder (cameras, images; text or binary)")
    q.add_argument("images", type=Path, help="folder the model's image names are relative to")
    q.add_argument("--out", type=Path, required=True, help="the new gallery folder")
    q.set_defaults(func=_gallery_import)
    q = verbs.add_parser("export", help="a gallery as a COLMAP model with its poses and no points")
    q.add_argument("gallery", type=Path, help="gallery folder")
    q.add_argument("--out", type=Path, required=True, help="model folder (COLMAP text format)")
    q.set_defaults(func=_gallery_export)

    p = sub.add_parser("build-map", help="features, matches and triangulation of a gallery")
    p.add_argument("gallery", type=Path, help="gallery folder (see `vlocbench gallery`)")
    p.add_argument("--method", default="sift", help="sift, orb-teblid, aliked-lightglue, ...")
    p.add_argument("--out", type=Path, help="map folder (default: maps/GALLERY/FEATURES-HASH)")
    p.add_argument(
        "--pairs",
        choices=("retrieval", "poses"),
        default="retrieval",
        help="top global-descriptor matches (the paper's) or the nearest cameras",
    )
    p.add_argument("--num-pairs", type=_count, default=25)
    p.add_argument(
        "--verification",
        choices=("epipolar", "sampson"),
        default="epipolar",
        help="hloc's epipolar-line test with the known poses, or the Sampson distance",
    )
    p.add_argument(
        "--min-track-length",
        type=_count,
        default=2,
        help="drop points seen in fewer images (2, the paper's: keep every point)",
    )
    p.add_argument(
        "--workers",
        type=_count,
        default=1,
        help="processes that extract a learned map's features and match its pairs (the same as one)",
    )
    p.add_argument("--overwrite", action="store_true", help="recompute cached stages")
    p.set_defaults(func=_build_map)

    p = sub.add_parser("localize", help="localize one image against a map")
    p.add_argument("image", type=Path)
    p.add_argument("--map", type=Path, required=True, help="map folder")
    p.add_argument("--camera", help="gallery camera that took the image (default: the first)")
    p.add_argument("--prior-image", help="gallery image whose pose is the prior (pose-prior maps)")
    p.set_defaults(func=_localize)

    p = sub.add_parser(
        "train-retrieval",
        help="train the NetVLAD place descriptor on towns and conditions of your choice",
        description="Renders the noon galleries of TOWNS' towns and queries under the setups of "
        "the --conditions files, then trains NetVLAD over frozen EfficientNet-Lite0 features "
        "(vlocbench.bench.retrieval_training). Use towns no experiment drives.",
    )
    p.add_argument("towns", type=Path, help="an experiment file: its towns, gallery and cache")
    p.add_argument(
        "--conditions",
        type=Path,
        action="append",
        required=True,
        help="an experiment file whose setups' conditions the queries are drawn from (repeat)",
    )
    p.add_argument("--output", type=Path, required=True, help="the weights file to write (.npz)")
    p.add_argument(
        "--data", type=Path, help="the rendered set: read if it exists, else rendered and written"
    )
    p.add_argument("--epochs", type=_count, help="passes over the queries (default 8)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_train_retrieval)


def _add_ros_verbs(sub: Any, shared: dict[str, argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "ros", help="ROS 2 nodes (needs the ros extra: pip install 'vlocbench[ros]')"
    )
    verbs = p.add_subparsers(dest="ros_command", required=True, metavar="NODE")
    q = verbs.add_parser(
        "localize",
        help="the paper's visual localization node on a map",
        description="Parameters as the paper's node names them; set them after the options with "
        "--ros-args -p NAME:=VALUE or --ros-args --params-file FILE.yaml (everything from "
        "--ros-args on goes to rclpy).",
    )
    q.add_argument("--map", type=Path, required=True, help="map folder (vlocbench build-map)")
    q.set_defaults(func=_ros_localize)
    q = verbs.add_parser(
        "sim",
        parents=[shared["town"]],
        help="the simulator as a ROS 2 world (clock, cameras, odometry, cmd_vel)",
        description="Parameters: camera_rate_hz (2), real_time_factor (1; 0: as fast as "
        "possible), seed; set them with --ros-args -p NAME:=VALUE.",
    )
    q.add_argument("--config", type=Path, help="YAML with conditions and cameras (as experiments)")
    q.set_defaults(func=_ros_sim)


def _ros_localize(args: argparse.Namespace) -> int:
    def load() -> Any:
        from rclpy.parameter import Parameter

        from vlocbench.ros.localization_node import LocalizationNode

        map_dir = Parameter("map_dir", Parameter.Type.STRING, str(args.map))
        return lambda: LocalizationNode(parameter_overrides=[map_dir])

    return _spin_node(load, args.ros_args)


def _ros_sim(args: argparse.Namespace) -> int:
    def load() -> Any:
        from vlocbench.ros.sim_node import SimulatorNode

        return lambda: SimulatorNode(args.town, args.config)

    return _spin_node(load, args.ros_args)


def _spin_node(load: Any, ros_args: list[str]) -> int:
    """Start rclpy (discovery on this machine unless set), spin the node that ``load()``'s
    constructor builds until Ctrl-C or SIGTERM, and clean up. ``load`` imports the node's module
    before ``rclpy.init``, so that rclpy's signal handlers are the last installed."""
    from vlocbench.ros.environment import local_only

    local_only()
    try:
        import rclpy

        make = load()
    except ImportError as exc:
        raise _missing_ros_extra(exc) from None
    from rclpy.executors import ExternalShutdownException

    rclpy.init(args=["vlocbench", *ros_args])
    node = None
    try:
        node = make()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):  # Ctrl-C, SIGTERM (rclpy's handlers)
        pass
    except Exception:
        # a signal that shuts the context down while the executor builds its wait set surfaces
        # as an RCLError ("the given context is not valid"): that too is a clean stop
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


EXPERIMENT_HELP = (
    "this experiment file: every episode of it in OUTPUT, whichever runs drove its parts "
    "(default: the latest run)"
)


def _add_experiment_verbs(sub: Any, shared: dict[str, argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "verify",
        help="drive stored episodes again and compare them with their stored results",
    )
    p.add_argument("output", type=Path, help="the experiment's output folder")
    p.add_argument("--experiment", type=Path, help=EXPERIMENT_HELP)
    p.add_argument(
        "--count", type=_count, default=1, help="how many episodes to drive again (default 1)"
    )
    p.add_argument(
        "--kinds",
        type=_names,
        help="only of these kinds (comma-separated: recall, failure, baseline)",
    )
    p.add_argument(
        "--methods", type=_names, help="only of these methods (comma-separated; odometry: the line)"
    )
    p.add_argument("--key", action="append", help="this episode (repeat for more); not --count")
    p.add_argument("--seed", type=int, default=0, help="seed of the choice of episodes")
    p.set_defaults(func=_verify)

    p = sub.add_parser(
        "platform",
        help="this machine's platform (what its renders and kernels compute), and stores' against it",
    )
    p.add_argument(
        "output", type=Path, nargs="*", help="output folders whose episodes' platforms to compare"
    )
    p.add_argument("--json", action="store_true", help="the whole record as JSON")
    p.set_defaults(func=_platform)

    p = sub.add_parser(
        "run",
        parents=[shared["report"]],
        help="run an experiment file: galleries, maps, episodes, then the report",
    )
    p.add_argument("experiment", type=Path, help="experiment YAML (see experiments/)")
    p.add_argument("--workers", type=_count, help="local worker processes (default: one per core)")
    p.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://127.0.0.1:8786")
    p.add_argument("--output", type=Path, help="output folder (default: the experiment's)")
    p.add_argument("--towns", type=_names, help="only these of its towns (comma-separated)")
    p.add_argument(
        "--methods",
        type=_names,
        help="only these of its methods (comma-separated); a later run of the whole "
        "experiment reuses their episodes",
    )
    p.add_argument(
        "--kinds",
        type=_names,
        help="only these kinds of its episodes (comma-separated: recall, failure, baseline), "
        "e.g. the recall drives of a long sweep first",
    )
    p.add_argument(
        "--setup",
        action="append",
        help="only this setup of its sweep, by its label (k=0 or illumination.k=0; a grouped "
        "level by its fields, 'dz_m=4, pitch_down_deg=22.5'; where several keys are swept, one "
        "key's level, k=8, names every setup at it; repeat the option for more)",
    )
    p.add_argument(
        "--repetitions",
        type=_count,
        help="only the first N failure and odometry-only drives of each setup: a long sweep's "
        "whole shape first, its spread later",
    )
    p.add_argument(
        "--reuse",
        type=Path,
        action="append",
        metavar="OUTPUT",
        help="another experiment's output folder: its finished episodes that this run shares "
        "(the same keys) are copied instead of driven again (repeat for more)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-report", action="store_true", help="skip the report")
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="make nothing: print the episodes done and left, the galleries and maps to make, "
        "and the hours the drives would take, from the store's own episode times",
    )
    p.set_defaults(func=_run)

    p = sub.add_parser(
        "cache",
        help="the galleries and maps experiments share: sizes, and what given experiments no "
        "longer use",
    )
    p.add_argument("--cache", type=Path, default=Path("out/cache"), help="the cache folder")
    p.add_argument(
        "--keep",
        type=Path,
        nargs="+",
        metavar="EXPERIMENT",
        help="experiment YAMLs whose galleries and maps are in use; the rest is marked unused",
    )
    p.add_argument(
        "--delete", action="store_true", help="with --keep: remove the unused galleries and maps"
    )
    p.set_defaults(func=_cache)

    p = sub.add_parser("export", help="a run's episodes for evo, hloc, COLMAP or ROS 2 tools")
    p.add_argument("output", type=Path, help="the experiment's output folder")
    how = p.add_mutually_exclusive_group(required=True)
    how.add_argument(
        "--format",
        help="tum, kitti (trajectories), hloc (recall drives' results), "
        "colmap (the galleries as posed models): in OUTPUT/export/FORMAT",
    )
    how.add_argument(
        "--rosbag",
        action="store_true",
        help="each episode as a rosbag2 (MCAP) folder in OUTPUT/bags (needs the ros extra)",
    )
    p.add_argument(
        "--images",
        action="store_true",
        help="with --rosbag: the query images too (JPEG, rendered again from the truth)",
    )
    p.add_argument("--experiment", type=Path, help=EXPERIMENT_HELP)
    p.set_defaults(func=_export)

    p = sub.add_parser("view", help="an episode in 3D: a rerun recording (needs the view extra)")
    p.add_argument("output", type=Path, help="the experiment's output folder")
    p.add_argument(
        "--episode",
        help="episode key (or its start), of any run; else the first of --setup/--method",
    )
    p.add_argument("--setup", help="setup label, e.g. k=6 (see the report)")
    p.add_argument("--method", help="method name, or odometry for the baseline")
    p.add_argument("--town", help="town name (where the store holds several)")
    # the episode kinds (bench.records.EPISODE_KINDS, not imported: the CLI starts without bench)
    p.add_argument("--kind", choices=("failure", "recall", "baseline"), help="drive kind")
    p.add_argument("--repetition", type=_index, help="repetition number, from 0")
    p.add_argument("--failed", action="store_true", help="the first drive that failed")
    p.add_argument(
        "--images",
        action="store_true",
        help="render the query images again and show the retrieved gallery images",
    )
    p.add_argument("--out", type=Path, help="recording file (default: OUTPUT/view/KEY.rrd)")
    p.add_argument("--spawn", action="store_true", help="also open the rerun viewer")
    p.add_argument("--experiment", type=Path, help=EXPERIMENT_HELP)
    p.set_defaults(func=_view)

    p = sub.add_parser(
        "report",
        parents=[shared["report"]],
        help="tables, figures and an HTML page of a run's results",
    )
    p.add_argument("output", type=Path, help="the experiment's output folder")
    p.add_argument("--experiment", type=Path, help=EXPERIMENT_HELP)
    p.set_defaults(func=_report)


EXIT_CODES = f"""exit codes:
  0  done
  {EXIT_INPUT}  bad input or data: an unknown name, an invalid value (the message names the field),
     a missing or damaged file, episodes that ended in errors
  {EXIT_USAGE}  the command line is wrong (unknown option, missing or malformed argument)
  {EXIT_MACHINE}  the machine stops it: no OpenGL, a full disk, an output folder another run holds
  {EXIT_INTERRUPTED}  interrupted (Ctrl-C, SIGINT or SIGTERM); a rerun resumes
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="vlocbench",
        description="Benchmark visual localization in closed-loop navigation on procedural "
        "MuJoCo-rendered towns.",
        epilog=EXIT_CODES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"vlocbench {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log details (debug level)")
    parser.add_argument("-q", "--quiet", action="store_true", help="log warnings and errors only")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    shared = _parents()
    for add in (
        _add_town_verbs,
        _add_drive_verb,
        _add_map_verbs,
        _add_experiment_verbs,
        _add_ros_verbs,
    ):
        add(sub, shared)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # ROS's own arguments (``--ros-args ...``) go to rclpy untouched
    cut = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    parser = build_parser()
    args = parser.parse_args(argv[:cut])  # exits with EXIT_USAGE on a bad command line
    if args.func is _export and args.images and not args.rosbag:
        parser.error("export --images: query images go into rosbags only; add --rosbag")
    args.ros_args = argv[cut:]
    _configure_logging(
        logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO
    )
    if args.verbose:  # the native libraries' lines too, in this process and its workers
        os.environ[NATIVE_LOG_ENV] = "1"
    # the ROS 2 verbs stop on rclpy's own handlers; every other command stops as Ctrl-C does
    ros_node = args.func in (_ros_localize, _ros_sim)
    try:
        with contextlib.nullcontext() if ros_node else _signals_interrupt():
            return int(args.func(args))
    except VlocbenchError as exc:
        print(f"vlocbench: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:  # a file system or device failure we did not anticipate
        print(f"vlocbench: error: {exc}", file=sys.stderr)
        return EXIT_MACHINE
    except KeyboardInterrupt:
        print(
            "vlocbench: interrupted; what finished is stored, run it again to resume",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED


class _StderrHandler(logging.Handler):
    """Plain messages on the current ``sys.stderr`` (looked up per message, not kept)."""

    def emit(self, record: logging.LogRecord) -> None:
        print(self.format(record), file=sys.stderr, flush=True)


def _configure_logging(level: int) -> None:
    """The ``vlocbench`` logger: plain messages on stderr at ``level``."""
    logger = logging.getLogger("vlocbench")
    logger.setLevel(level)
    if not any(isinstance(h, _StderrHandler) for h in logger.handlers):
        logger.addHandler(_StderrHandler())


if __name__ == "__main__":
    sys.exit(main())
