"""Rendering under conditions, on real renders of the small town (low resolution)."""

import itertools

import cv2
import numpy as np
import pytest

from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.geometry import invert_pose, planar_pose
from vlocbench.loc.registry import build_features
from vlocbench.sim import (
    Camera,
    Conditions,
    Exposure,
    Extrinsics,
    Headlights,
    Illumination,
    Intrinsics,
    Simulator,
    StreetLights,
    Weather,
    gallery_camera,
    generate_town,
    load_town_spec,
)
from vlocbench.sim.camera import project
from vlocbench.sim.light import tone_curve

SMALL = Intrinsics(320, 240, 90.0)


def render(sim, conditions, camera=None, waypoint=10):
    wp = sim.town.route.waypoints_xy[waypoint]
    sim.teleport(float(wp[0]), float(wp[1]), float(sim.town.route.yaw_rad[waypoint]))
    sim.set_conditions(conditions)
    camera = camera or Camera("g", SMALL, Extrinsics())
    # an explicit frame id: the noise would otherwise follow the clock of the session's shared
    # simulator, which other tests advance
    return sim.render([camera], frame_id=waypoint)[0]


def gray(frame):
    return cv2.cvtColor(frame.image, cv2.COLOR_RGB2GRAY).astype(np.float64)


def test_same_seed_same_image_bytes(small_town, small_sim):
    a = render(small_sim, Conditions(weather=Weather(rain=0.5))).image
    with Simulator(generate_town(small_town.spec)) as other:
        b = render(other, Conditions(weather=Weather(rain=0.5))).image
    assert a.shape == (240, 320, 3) and a.dtype == np.uint8
    assert a.tobytes() == b.tobytes()


def test_brightness_falls_with_k(small_sim):
    fixed, unlit = Exposure("fixed"), StreetLights("off")
    means = [
        gray(
            render(
                small_sim,
                Conditions(illumination=Illumination(k=k), exposure=fixed, street_lights=unlit),
            )
        ).mean()
        for k in (0, 2, 4, 10)
    ]
    assert all(a > b for a, b in itertools.pairwise(means[:3])), means
    assert means[-1] < 1 < 60 < means[0]  # without adapting, night is black


def test_auto_exposure_keeps_dusk_bright(small_sim):
    # the sun facing the view's facades (at the default azimuth they are lit by the sky alone,
    # and the camera meters the light on the ground)
    noon = render(small_sim, Conditions(illumination=Illumination(sun_azimuth_deg=135))).image
    noon = noon.astype(float)
    dusk = Illumination(k=4, sun_azimuth_deg=135)
    fixed = render(small_sim, Conditions(illumination=dusk, exposure=Exposure("fixed"))).image
    auto = render(small_sim, Conditions(illumination=dusk)).image.astype(float)
    gain = small_sim.renderer.gain
    assert 30 < gain < 96  # 1/16 of the sun at 4.7 degrees: about 6 stops darker than noon
    assert fixed.mean() < auto.mean() / 4  # without adapting, dusk is dark
    assert abs(auto.mean() - noon.mean()) < 0.25 * noon.mean()  # the camera opens up
    # the default camera (CARLA's kind) adds no noise: another frame is the same image
    again = small_sim.render([Camera("g", SMALL, Extrinsics())], frame_id=11)[0].image
    assert np.array_equal(again, auto)
    # the shot-noise option pays for its gain, the noise growing as the square root of the gain
    grain = np.abs(np.diff(auto, axis=1)).mean()
    noisy = Exposure(max_gain=65536.0, shot_noise=0.03)
    auto_noisy = render(small_sim, Conditions(illumination=dusk, exposure=noisy)).image
    assert np.abs(np.diff(auto_noisy.astype(float), axis=1)).mean() > 2.5 * grain


def test_contrast_falls_with_exponential_fog(small_sim):
    front = Camera("front", SMALL, Extrinsics(z_m=1.6, yaw_deg=0.0))
    stds = [
        gray(
            render(
                small_sim,
                Conditions(weather=Weather(fog_visual_range_m=v, fog_model="exponential")),
                front,
            )
        ).std()
        for v in (None, 60.0, 10.0)
    ]
    assert stds[0] > stds[1] > stds[2], stds


def test_paper_fog_starts_at_the_visual_range(small_sim):
    """CARLA's fog as the paper set it: clear before the visual range, opaque soon after; the
    exponential option fogs the road just in front of the camera too."""
    front = Camera("front", SMALL, Extrinsics(z_m=1.6, yaw_deg=0.0))
    clear = gray(render(small_sim, Conditions(), front))
    starts = gray(render(small_sim, Conditions(weather=Weather(fog_visual_range_m=10.0)), front))
    exp = Weather(fog_visual_range_m=10.0, fog_model="exponential")
    exponential = gray(render(small_sim, Conditions(weather=exp), front))
    near = slice(-20, None)  # the road 2-3 m ahead
    assert np.abs(starts[near] - clear[near]).mean() < 1.0
    assert np.abs(exponential[near] - clear[near]).mean() > 10.0
    far = (slice(95, 118), slice(0, 150))  # the far end of the street, beyond 15 m
    assert clear[far].std() > 10.0 and starts[far].std() < 1.0  # uniform fog


def test_winter_differs_from_summer(small_sim):
    summer = render(small_sim, Conditions()).image.astype(np.float64)
    winter = render(small_sim, Conditions(season="winter")).image.astype(np.float64)
    assert np.abs(summer - winter).mean() > 5
    # snow on the sidewalk in the lower part of the image
    assert winter[-60:].mean() > summer[-60:].mean() + 10


def test_headlights_light_the_road_at_night(small_sim):
    front = Camera("front", SMALL, Extrinsics(z_m=1.6, yaw_deg=0.0, pitch_deg=5.0))
    unlit = StreetLights("off")
    dark = gray(
        render(small_sim, Conditions(illumination=Illumination(k=10), street_lights=unlit), front)
    )
    assert small_sim.renderer.exposure_share < 0.01  # far beyond the camera's range
    night = Conditions(
        illumination=Illumination(k=10), headlights=Headlights(on=True), street_lights=unlit
    )
    lit = gray(render(small_sim, night, front))
    assert small_sim.renderer.exposure_share == 1.0  # the meter sees the headlights
    road = slice(SMALL.height // 2 + 20, None)
    assert dark[road].mean() < 5 and lit[road].mean() > 20


def lamp_view(sim):
    """A camera 8 m before the town's first lamp, looking along its curb, a little up (320x240)."""
    x, y, yaw = sim.town.lamps[0]
    # stand on the road beside the lamp, 8 m before it along the curb, facing along the curb
    along = np.array([np.sin(yaw), -np.cos(yaw)])
    road = np.array([np.cos(yaw), np.sin(yaw)])
    at = np.array([x, y]) + 3.0 * road - 8.0 * along
    sim.teleport(float(at[0]), float(at[1]), float(np.arctan2(along[1], along[0])))
    return Camera("front", SMALL, Extrinsics(x_m=0.0, z_m=1.6, yaw_deg=0.0, pitch_deg=-15.0))


def night_image(sim, camera, street_lights):
    night = Conditions(illumination=Illumination(k=10), street_lights=street_lights)
    sim.set_conditions(night)
    return sim.render([camera], frame_id=0)[0].image


def test_street_lights_are_on_at_night_only_and_light_the_road(small_sim):
    camera = lamp_view(small_sim)
    lit = night_image(small_sim, camera, StreetLights())
    assert small_sim.renderer.street_lights_on  # k = 10: below the photocell's threshold
    unlit = night_image(small_sim, camera, StreetLights("off"))
    lit_grey, unlit_grey = (cv2.cvtColor(i, cv2.COLOR_RGB2GRAY).astype(float) for i in (lit, unlit))
    road = slice(-50, None)
    assert unlit_grey[road].mean() < 5
    assert lit_grey[road].mean() > unlit_grey[road].mean() + 5  # a pool of light
    assert lit_grey.max() > 200  # the lamp's head glows
    # by day they are off, and the day's images are as without them, byte for byte
    small_sim.set_conditions(Conditions(illumination=Illumination(k=4)))
    assert not small_sim.renderer.street_lights_on
    day = small_sim.render([camera], frame_id=0)[0].image
    small_sim.set_conditions(
        Conditions(illumination=Illumination(k=4), street_lights=StreetLights("off"))
    )
    assert day.tobytes() == small_sim.render([camera], frame_id=0)[0].image.tobytes()


def test_lit_windows_follow_their_share(small_sim):
    camera = Camera("g", SMALL, Extrinsics())
    wp = small_sim.town.route.waypoints_xy[10]
    small_sim.teleport(float(wp[0]), float(wp[1]), float(small_sim.town.route.yaw_rad[10]))
    none, some, every = (
        night_image(
            small_sim, camera, StreetLights(mode="on", lamp_illuminance=0.0, window_share=s)
        )
        for s in (0.0, 0.3, 1.0)
    )
    # windows: false, a town whose buildings have no lights: no window lit, none black glass
    bare = night_image(
        small_sim,
        camera,
        StreetLights(mode="on", lamp_illuminance=0.0, window_share=1.0, windows=False),
    )
    warm = [((i[..., 0].astype(int) - i[..., 2]) > 15).mean() for i in (none, some, every, bare)]
    assert warm[0] < 0.001 < warm[1] < warm[2], warm  # warm light in a share of the windows
    assert warm[3] < 0.001, warm
    black = (none.max(axis=2) == 0).mean(), (bare.max(axis=2) == 0).mean()
    assert black[1] < 0.1 * black[0], black  # the windows show what they show by day, dimly


def test_street_lights_bad_input_names_the_field():
    with pytest.raises(UnknownNameError, match=r"street_lights\.mode.*auto"):
        StreetLights(mode="dusk")
    with pytest.raises(ConfigError, match=r"street_lights\.window_share"):
        StreetLights(window_share=1.5)
    with pytest.raises(ConfigError, match=r"street_lights\.lamp_illuminance"):
        StreetLights(lamp_illuminance=-1.0)
    with pytest.raises(ConfigError, match=r"street_lights\.windows"):
        StreetLights(windows="no")  # type: ignore[arg-type]


def test_sun_shadows_darken_what_the_sun_cannot_reach_and_keep_the_skylight(small_sim):
    sun = Illumination(k=2)
    lit = gray(render(small_sim, Conditions(illumination=sun)))
    shaded = gray(render(small_sim, Conditions(illumination=sun, shadows=True)))
    darker = lit - shaded
    in_shadow = darker > 10
    assert in_shadow.mean() > 0.1  # the facade across the street and the pavement before it
    assert (darker < -3).mean() == 0  # a shadow never brightens
    # the sky still lights the shade: about half of the sunlit brightness, not black
    assert 0.4 < (shaded[in_shadow] / lit[in_shadow]).mean() < 0.7
    assert np.array_equal(gray(render(small_sim, Conditions(illumination=sun))), lit)
    with pytest.raises(ConfigError, match="shadows"):
        Conditions(shadows="yes")


def test_projection_matches_the_render(small_sim):
    camera = Camera(
        "odd",
        Intrinsics(640, 480, 75.0),
        Extrinsics(x_m=1.0, y_m=0.2, z_m=1.8, roll_deg=3, pitch_deg=5, yaw_deg=10),
    )
    wp = small_sim.town.route.waypoints_xy[5]
    world_from_vehicle = planar_pose(
        float(wp[0]), float(wp[1]), float(small_sim.town.route.yaw_rad[5])
    )
    world_from_cam = camera.world_from_cam(world_from_vehicle)
    rng = np.random.default_rng(0)
    pts_cam = np.stack(
        [rng.uniform(-1.5, 1.5, 12), rng.uniform(-1.0, 1.0, 12), rng.uniform(5, 9, 12)], 1
    )
    pts_world = pts_cam @ world_from_cam[:3, :3].T + world_from_cam[:3, 3]
    i = camera.intrinsics
    image = small_sim.renderer.render(
        world_from_cam, i.width, i.height, i.fov_deg, markers_world=pts_world, marker_radius_m=0.08
    )
    mask = ((image[..., 0] > 200) & (image[..., 1] < 40) & (image[..., 2] < 40)).astype(np.uint8)
    _n, _, stats, centroids = cv2.connectedComponentsWithStats(mask)
    found = centroids[1:][stats[1:, cv2.CC_STAT_AREA] > 10]
    expected, depth = project(i.K, invert_pose(world_from_cam), pts_world)
    assert (depth > 0).all()
    assert len(found) >= 10  # a few may overlap
    errors = np.linalg.norm(found[:, None] - expected[None], axis=2).min(axis=1)
    assert np.median(errors) < 0.3 and errors.max() < 0.8, errors


def test_ego_car_is_not_seen_by_its_cameras(small_sim):
    """A camera 8 m behind the car, looking along it: the car's back shows below the middle of its
    view when its geom group is drawn, and nowhere in the default render."""
    from vlocbench.sim.scene import GROUP_EGO

    chase = Camera("chase", SMALL, Extrinsics(x_m=-8.0, z_m=2.0, yaw_deg=0.0, pitch_deg=-5.0))
    hidden = render(small_sim, Conditions(), chase).image
    renderer = small_sim.renderer
    groups = renderer.option.geomgroup.copy()
    try:
        renderer.option.geomgroup[GROUP_EGO] = 1
        drawn = small_sim.render([chase], frame_id=10)[0].image
    finally:
        renderer.option.geomgroup[:] = groups
    changed = np.abs(drawn.astype(int) - hidden).sum(axis=2) > 30
    assert changed[145:178, 138:182].mean() > 0.9  # the car's back, 8 m ahead
    assert changed.mean() < 0.05  # and nothing else
    assert (render(small_sim, Conditions(), chase).image == hidden).all()


def test_the_papers_sift_finds_enough_keypoints_on_town01_gallery_images():
    """About 250 a view since the sidewalks lost their grout lines (600 with them, half of them
    on the lines' look-alike crossings; a median of 270 on scene 7, 246 on scene 8, whose new
    grass moved the draws of the textures after it, the trees' leaves among them); in front of the
    concrete panels of the route's first street, in the shade at noon, 105-180 since they have a
    grain (35-80 without it)."""
    town = generate_town(load_town_spec("town01"))
    sift = build_features("sift")
    counts, panels = [], []
    with Simulator(town) as sim:
        for idx in np.linspace(10, len(town.route.waypoints_xy) - 10, 9).astype(int):
            x, y = town.route.waypoints_xy[idx]
            sim.teleport(float(x), float(y), float(town.route.yaw_rad[idx]))
            image = sim.render([gallery_camera()])[0].image
            counts.append(len(sift.extract(image)))
        for x in (82.0, 86.0, 90.0, 94.0, 98.0):
            sim.teleport(x, -2.0, 0.0)
            panels.append(len(sift.extract(sim.render([gallery_camera()])[0].image)))
    assert np.median(counts) >= 225, counts
    assert min(panels) >= 90, panels


def test_beyond_its_range_the_camera_records_the_share_of_exposure_it_reached(small_sim):
    """A camera that cannot open up enough records the metered image darkened through its gamma:
    display values times (reached / needed exposure)^(1/2.2), not times the share itself."""
    dusk = Illumination(k=4)
    full = render(small_sim, Conditions(illumination=dusk, exposure=Exposure(shot_noise=0.0)))
    needed = small_sim.renderer.gain
    short = Exposure(max_gain=4.0, shot_noise=0.0)
    dark = render(small_sim, Conditions(illumination=dusk, exposure=short))
    assert small_sim.renderer.gain == 4.0
    share = 4.0 / needed
    expected = (share ** (1 / 2.2)) * full.image.astype(float).mean()
    assert dark.image.astype(float).mean() == pytest.approx(expected, rel=0.03)
    assert dark.image.mean() > 3 * share * full.image.mean()  # far brighter than linear


def test_carlas_tone_curve_blacks_out_the_unlit_night_and_keeps_noon(small_sim):
    """``tone_curve: filmic`` maps every rendered grey level through CARLA's camera curve: at noon
    much the same picture, at night (k = 10) the dimly lit facades fall to black."""
    filmic = Exposure(tone_curve="filmic")
    lut = tone_curve("filmic")
    assert lut is not None
    for k in (0, 10):
        plain = render(small_sim, Conditions(illumination=Illumination(k=k)))
        toned = render(small_sim, Conditions(illumination=Illumination(k=k), exposure=filmic))
        # a lookup on the render, pixel for pixel (the default camera adds no noise)
        np.testing.assert_array_equal(toned.image, lut[plain.image])
        dark_plain, dark_toned = (np.mean(gray(f) <= 5) for f in (plain, toned))
        if k == 0:
            assert gray(toned).mean() == pytest.approx(gray(plain).mean(), rel=0.25)
        else:
            assert dark_toned > dark_plain + 0.3, (dark_plain, dark_toned)


def test_an_aliased_camera_sees_the_same_scene_with_harder_edges(small_sim):
    """``antialias=False`` (the default) samples each pixel once: the same picture as 4 samples,
    only edge pixels differ (each keeps its own GL context, so the two kinds of image interleave)."""
    smooth_cam = Camera("g", SMALL, Extrinsics(), antialias=True)
    hard_cam = Camera("g", SMALL, Extrinsics())
    smooth = render(small_sim, Conditions(), smooth_cam).image.astype(np.int16)
    hard = render(small_sim, Conditions(), hard_cam).image.astype(np.int16)
    again = render(small_sim, Conditions(), smooth_cam).image.astype(np.int16)
    np.testing.assert_array_equal(again, smooth)
    changed = np.abs(hard - smooth).max(axis=2) > 10
    assert 0 < changed.mean() < 0.05
    # what changed lies on edges: next to a strong gradient of the smooth image
    edges = cv2.dilate(cv2.Canny(smooth.astype(np.uint8), 50, 150), np.ones((3, 3), np.uint8))
    assert (edges[changed] > 0).mean() > 0.9


def test_depth_is_the_distance_along_the_optical_axis_to_the_scene(small_sim):
    """Looking straight down on the road from 12 m: every road pixel is 12 m away along the
    axis, and the sky straight up is at the far plane."""
    wp = small_sim.town.route.waypoints_xy[5]
    down = np.eye(4)
    down[:3, :3] = np.diag([1.0, -1.0, -1.0])  # optical axis -z (down), image y along -y
    down[:3, 3] = [wp[0], wp[1], 12.0]
    depth = small_sim.renderer.render_depth(down, 64, 48, 30.0)
    assert depth.shape == (48, 64) and depth.dtype == np.float32
    assert np.allclose(np.median(depth), 12.0, atol=0.05)
    up = down.copy()
    up[:3, :3] = np.diag([1.0, 1.0, 1.0])  # optical axis +z
    up[2, 3] = 200.0  # above every roof
    assert np.all(small_sim.renderer.render_depth(up, 64, 48, 30.0) > 1000)


def test_clouds_from_the_suns_intensity_render_as_that_overcast(small_sim):
    """scenario_runner's cover (1 - I, 94 % at k = 4) is the weather's overcast at that cover."""
    clouded = Illumination(k=4, cloud_cover="from_intensity")
    a = render(small_sim, Conditions(illumination=clouded)).image
    b = render(
        small_sim, Conditions(illumination=Illumination(k=4), weather=Weather(overcast=0.9375))
    ).image
    clear = render(small_sim, Conditions(illumination=Illumination(k=4))).image
    assert a.tobytes() == b.tobytes()
    assert np.abs(a.astype(int) - clear.astype(int)).mean() > 1.0
