"""Headless rendering of a town scene under given conditions (MuJoCo's classic renderer).

Conditions change model parameters in place (lights, materials, sky texture, geom groups) and GL
fog state; nothing is recompiled. Cameras are set directly in the MuJoCo scene (position, axes,
frustum from the intrinsics), so rendered images agree with ``Camera.world_from_cam`` and
``Intrinsics.K`` to sub-pixel precision.
"""

from __future__ import annotations

import zlib

import mujoco
import numpy as np
from numpy.typing import NDArray

from vlocbench.interfaces import Image
from vlocbench.sim import textures as tex
from vlocbench.sim.backend import missing_libraries_error, select_backend
from vlocbench.sim.camera import Intrinsics
from vlocbench.sim.conditions import Conditions
from vlocbench.sim.light import (
    DISPLAY_GAMMA,
    NOON_AMBIENT,
    daylight,
    exposure_gain,
    sensor_noise,
    tone_curve,
)
from vlocbench.sim.rain import apply_puddles, apply_rain
from vlocbench.sim.scene import (
    GROUP_COLLISION,
    GROUP_EGO,
    GROUP_FOLIAGE_FULL,
    GROUP_FOLIAGE_SPARSE,
    LAMP_HEIGHT_M,
    LAMP_REACH_M,
    NIGHT_MESHES,
    NIGHT_PARKED_Z_M,
    SKY_SIZE,
    TownScene,
)

NEAR_M, FAR_M = 0.1, 2000.0
# what the camera's light meter reads of the car's own headlights, per unit of their intensity
HEADLIGHT_METERING = 0.2
ANTIALIAS_SAMPLES = 4  # MuJoCo's default multisampling of offscreen images
# MuJoCo's classic renderer draws with OpenGL's fixed-function lights: at most 8 in a frame
# (measured: a 9th and later lights of the scene add nothing)
MAX_FRAME_LIGHTS = 8
# lamps are lit nearest first to this point ahead of the camera, and the sun's shadows are
# drawn around it
VIEW_AIM_AHEAD_M = 15.0
# half the side of the square the sun's shadow map covers (1024 texels: 12 cm each), and how far
# back towards the sun its light is placed (the shadow map's depth starts there)
SHADOW_HALF_WIDTH_M = 60.0
SHADOW_LIGHT_BACK_M = 500.0
LEAVES = {"summer": (0.33, 0.55, 0.22), "autumn": (0.85, 0.45, 0.12), "winter": (0.5, 0.5, 0.5)}


def sky_colors(c: Conditions, brightness: float) -> tuple[NDArray, NDArray]:
    """Zenith and horizon colours (RGB in [0, 1]) of a sky of exposed ``brightness`` (0-1)."""
    ill, w = c.illumination, c.weather
    dusk = float(np.clip(1 - ill.sun_elevation_rad / np.radians(15), 0, 1))  # low sun: warm horizon
    zenith = (
        np.array([0.30, 0.50, 0.85]) * (1 - 0.3 * dusk) + np.array([0.2, 0.2, 0.4]) * 0.3 * dusk
    )
    horizon = np.array([0.75, 0.82, 0.92]) * (1 - dusk) + np.array([0.95, 0.62, 0.38]) * dusk
    grey = np.array([0.62, 0.64, 0.67])
    zenith = zenith * (1 - c.overcast) + grey * c.overcast
    horizon = horizon * (1 - c.overcast) + grey * 1.05 * c.overcast
    if w.fog_visual_range_m is not None:
        fog = fog_color(c, brightness)
        # the sky lies beyond any fog that starts at a distance; exponential fog leaves some blue
        mix = (
            1.0
            if w.fog_model == "starts_at"
            else float(np.clip(60.0 / w.fog_visual_range_m, 0.5, 1.0))
        )
        return zenith * brightness * (1 - mix) + fog * mix, fog
    return zenith * brightness, horizon * brightness


def fog_color(c: Conditions, brightness: float) -> NDArray:
    return np.array([0.72, 0.74, 0.76]) * brightness * (1 - 0.2 * c.weather.rain)


class Renderer:
    """Renders RGB images of ``scene`` from arbitrary camera poses under ``apply``-ed conditions."""

    def __init__(self, scene: TownScene, conditions: Conditions | None = None) -> None:
        self.scene = scene
        self.backend = select_backend()
        self._renderers: dict[tuple[int, int, int], mujoco.Renderer] = {}
        self.option = mujoco.MjvOption()
        self.conditions = conditions or Conditions()
        self._night_z = scene.model.geom_pos[list(scene.night_geom_ids), 2].copy()
        self._window_share = 0.0  # as the scene is built
        # the facades' gloss as built, to wet (their colours as built are scene.base_rgba)
        self._facade_gloss = {
            name: (float(scene.model.mat_specular[i]), float(scene.model.mat_shininess[i]))
            for name, i in scene.material_ids.items()
            if name.startswith(("facade", "tower", "shops"))
        }
        self.apply(self.conditions)

    # -- conditions -----------------------------------------------------------------------------
    def apply(self, conditions: Conditions) -> None:
        """Set lights, sky, materials and foliage for ``conditions`` (no recompilation)."""
        self.conditions = conditions
        m, sc = self.scene.model, self.scene
        ill, w = conditions.illumination, conditions.weather
        elevation = ill.sun_elevation_rad
        az = np.radians(ill.sun_azimuth_deg)
        # light travels from the sun towards the ground
        m.light_dir[sc.sun_light_id] = -np.array(
            [np.cos(elevation) * np.cos(az), np.cos(elevation) * np.sin(az), np.sin(elevation)]
        )
        dusk = float(np.clip(1 - elevation / np.radians(15), 0, 1))
        sun_color = np.array([1.0, 0.97, 0.92]) * (1 - dusk) + np.array([1.0, 0.7, 0.45]) * dusk
        light = daylight(
            ill.sun_intensity, elevation, conditions.overcast, ill.sun_elevation_base_rad
        )
        h = conditions.headlights
        e = conditions.exposure
        noon = daylight(1.0, ill.sun_elevation_base_rad, 0.0, ill.sun_elevation_base_rad)
        headlight_reading = HEADLIGHT_METERING * h.intensity if h.on else 0.0
        self._tone = tone_curve(e.tone_curve)  # applied to each finished image (render)
        # the scene is lit as the camera records it (MuJoCo's colours are display values): at
        # the metered exposure g where the camera reaches it; one that cannot (beyond its range,
        # or fixed) records the share it reached, darker through its gamma
        g = exposure_gain(light, noon, headlight_reading, np.inf)
        self.gain = min(g, e.max_gain) if e.mode == "auto" else 1.0
        self.exposure_share = self.gain / g
        level = g * self.exposure_share ** (1 / DISPLAY_GAMMA)
        m.light_diffuse[sc.sun_light_id] = sun_color * light.direct * level
        m.light_ambient[sc.sun_light_id] = np.array([0.92, 0.95, 1.0]) * light.ambient * level
        m.light_specular[sc.sun_light_id] = 0.2 * light.direct * level
        for lid in sc.headlight_ids:
            m.light_active[lid] = h.on
            m.light_diffuse[lid] = np.array([1.0, 0.97, 0.88]) * h.intensity * level
            m.light_cutoff[lid] = h.cutoff_deg
        # the sky's luminance follows the skylight; displayed with a gamma of about 1 / 2.2
        self.sky_brightness = float(
            np.clip(light.ambient * g / NOON_AMBIENT, 0, 1) ** 0.45
            * self.exposure_share ** (1 / DISPLAY_GAMMA)
        )
        self._apply_street_lights(conditions, light.horizontal / noon.horizontal)
        self._apply_season(conditions)
        wet = w.ground_wetness
        for name in ("road", "intersection", "paving", "crosswalk"):
            for variant in ("", "_autumn", "_winter"):
                mid = sc.material_ids.get(name + variant)
                if mid is None:
                    continue
                base = sc.base_rgba[name + variant]
                m.mat_rgba[mid, :3] = base[:3] * (1 - 0.35 * wet)
                m.mat_specular[mid] = 0.05 + 0.6 * wet
                m.mat_shininess[mid] = 0.1 + 0.7 * wet
        # wet walls: darker (water fills the pores) and glossier
        for name, (specular, shininess) in self._facade_gloss.items():
            mid = sc.material_ids[name]
            m.mat_rgba[mid, :3] = sc.base_rgba[name][:3] * (1 - 0.2 * wet)
            m.mat_specular[mid] = specular + 0.3 * wet
            m.mat_shininess[mid] = shininess + 0.4 * wet * (1 - shininess)
        zenith, self._sky_horizon = sky_colors(conditions, self.sky_brightness)
        self._set_texture(
            sc.sky_texture_id, tex.sky(tuple(zenith), tuple(self._sky_horizon), SKY_SIZE)
        )
        # lights are drawn from data.light_xdir/xpos, which only mj_camlight derives from the
        # model's light_dir: without this the old sun shone until the next simulation step
        sc.forward()

    def _apply_street_lights(self, c: Conditions, daylight_share: float) -> None:
        """Lamps and lit windows on or off; their brightness as this camera records it (a
        white surface at noon displays 1)."""
        m, sc, sl = self.scene.model, self.scene, c.street_lights
        self.street_lights_on = sl.on(daylight_share)
        shown = {
            "lamp_glow": self.street_lights_on,
            "windows_lit": self.street_lights_on and sl.windows,
        }
        for name, gid, z in zip(NIGHT_MESHES, sc.night_geom_ids, self._night_z, strict=True):
            m.geom_pos[gid, 2] = z if shown[name] else z + NIGHT_PARKED_Z_M
        # under a lamp, the road's white would display this (a point light, 1/d in display
        # values: about 1/d^2 through the camera's gamma)
        self.lamp_level = (sl.lamp_illuminance * self.gain) ** (1 / DISPLAY_GAMMA)
        window = (sl.window_luminance * self.gain) ** (1 / DISPLAY_GAMMA)
        m.mat_emission[sc.material_ids["windows_lit"]] = min(window, 1.0)
        if sl.window_share != self._window_share:
            self._window_share = sl.window_share
            self._set_texture(sc.window_texture_id, tex.lit_windows(sl.window_share))

    def _apply_season(self, c: Conditions) -> None:
        m, sc = self.scene.model, self.scene
        suffix = {"summer": "", "autumn": "_autumn", "winter": "_winter"}[c.season]
        for family, geoms in sc.season_geoms.items():
            name = family + suffix if family + suffix in sc.material_ids else family
            for g in geoms:
                m.geom_matid[g] = sc.material_ids[name]
        for mat in ("leaves_full", "leaves_sparse"):
            m.mat_rgba[sc.material_ids[mat], :3] = LEAVES[c.season]
        groups = np.ones(6, np.uint8)
        groups[GROUP_COLLISION] = groups[GROUP_EGO] = 0
        groups[GROUP_FOLIAGE_FULL] = c.season == "summer"
        groups[GROUP_FOLIAGE_SPARSE] = c.season == "autumn"
        self.option.geomgroup[:] = groups

    def _set_texture(self, texture_id: int, image: NDArray[np.uint8]) -> None:
        """Replace a texture's pixels in the model and in every GL context made so far."""
        m = self.scene.model
        start = m.tex_adr[texture_id]
        m.tex_data[start : start + image.size] = image.ravel()
        for r in self._renderers.values():
            self._upload_texture(r, texture_id)

    def _upload_texture(self, r: mujoco.Renderer, texture_id: int) -> None:
        r._gl_context.make_current()
        mujoco.mjr_uploadTexture(self.scene.model, r._mjr_context, texture_id)

    # -- rendering ------------------------------------------------------------------------------
    def _renderer(self, width: int, height: int, samples: int) -> mujoco.Renderer:
        key = (width, height, samples)
        if key not in self._renderers:
            # the multisample count and the shadow map's extent are read when a context is
            # made: one context per count
            m = self.scene.model
            m.vis.quality.offsamples = samples
            m.vis.map.shadowclip = SHADOW_HALF_WIDTH_M / m.stat.extent
            try:
                r = mujoco.Renderer(self.scene.model, height, width, max_geom=20000)
            except Exception as exc:  # MuJoCo raises plain errors for missing GL libraries
                raise missing_libraries_error(self.backend, exc) from exc
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 1
            self._renderers[key] = r
            self._upload_texture(r, self.scene.sky_texture_id)
            self._upload_texture(r, self.scene.window_texture_id)
        return self._renderers[key]

    def _set_fog(self, r: mujoco.Renderer) -> None:
        from OpenGL import GL

        w = self.conditions.weather
        r.scene.flags[mujoco.mjtRndFlag.mjRND_FOG] = w.fog_visual_range_m is not None
        if w.fog_visual_range_m is None:
            return
        # MuJoCo reads its (linear) fog settings only when the context is made; set GL state.
        # Under fog it draws no skybox but clears to the context's fog colour: set that too.
        r._mjr_context.fogRGBA[:] = [*fog_color(self.conditions, self.sky_brightness), 1.0]
        r._gl_context.make_current()
        if w.fog_model == "starts_at":
            GL.glFogi(GL.GL_FOG_MODE, GL.GL_LINEAR)
            GL.glFogf(GL.GL_FOG_START, w.fog_visual_range_m)
            GL.glFogf(GL.GL_FOG_END, w.fog_visual_range_m + w.fog_ramp_m)
        else:
            GL.glFogi(GL.GL_FOG_MODE, GL.GL_EXP)
            GL.glFogf(GL.GL_FOG_DENSITY, w.fog_density_per_m)
        GL.glFogfv(GL.GL_FOG_COLOR, [*fog_color(self.conditions, self.sky_brightness), 1.0])

    def render(
        self,
        world_from_cam: NDArray[np.float64],
        width: int,
        height: int,
        fov_deg: float,
        frame_id: int = 0,
        markers_world: NDArray[np.float64] | None = None,
        marker_radius_m: float = 0.1,
        antialias: bool = False,
    ) -> Image:
        """RGB image (height, width, 3) from the optical-frame pose ``world_from_cam``.

        ``frame_id`` seeds per-frame effects (rain). ``markers_world`` (N, 3) draws unlit red
        spheres, e.g. to check projections. ``antialias``: 4 samples per pixel, else 1.
        """
        r, image = self._draw(
            world_from_cam, width, height, fov_deg, antialias, markers_world, marker_radius_m
        )
        rain = self.conditions.weather.rain
        seed = zlib.crc32(f"{self.scene.town.spec.seed}:{frame_id}".encode())
        deposits = self.conditions.weather.puddles
        if deposits > 0:
            image = apply_puddles(
                image,
                _depth_m(r, width, height),
                Intrinsics(width, height, fov_deg).K,
                world_from_cam,
                deposits,
                self.scene.town.spec.seed,
                self._sky_horizon,
                np.random.default_rng(seed + 2),
            )
        if rain > 0:
            image = apply_rain(
                image,
                rain,
                self.sky_brightness,
                self.conditions.weather.rain_streaks_per_kpx,
                np.random.default_rng(seed),
            )
        if self._tone is not None:
            image = self._tone[image]
        e = self.conditions.exposure
        return sensor_noise(
            image, self.gain, e.shot_noise, e.read_noise, np.random.default_rng(seed + 1)
        )

    def _draw(
        self,
        world_from_cam: NDArray[np.float64],
        width: int,
        height: int,
        fov_deg: float,
        antialias: bool = False,
        markers_world: NDArray[np.float64] | None = None,
        marker_radius_m: float = 0.1,
    ) -> tuple[mujoco.Renderer, Image]:
        """The scene drawn from ``world_from_cam``, before any image effect: the renderer (whose
        depth buffer holds the view) and its RGB image (height, width, 3)."""
        sc = self.scene
        r = self._renderer(width, height, ANTIALIAS_SAMPLES if antialias else 0)
        r.update_scene(sc.data, camera=-1, scene_option=self.option)
        half_w = NEAR_M * np.tan(np.radians(fov_deg) / 2)
        half_h = half_w * height / width
        rot, pos = world_from_cam[:3, :3], world_from_cam[:3, 3]
        for cam in r.scene.camera:
            cam.pos[:] = pos
            cam.forward[:] = rot[:, 2]
            cam.up[:] = -rot[:, 1]
            cam.frustum_center = 0.0
            cam.frustum_width = half_w
            cam.frustum_bottom, cam.frustum_top = -half_h, half_h
            cam.frustum_near, cam.frustum_far = NEAR_M, FAR_M
            cam.orthographic = 0
        aim = pos + VIEW_AIM_AHEAD_M * _horizontal(rot[:, 2])
        r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self.conditions.shadows
        if self.conditions.shadows:
            self._cast_sun_shadows(r.scene, aim)
        if self.street_lights_on:
            self._add_lamps(r.scene, aim)
        if markers_world is not None:
            self._add_markers(r.scene, markers_world, marker_radius_m, (1.0, 0.0, 0.0))
        self._set_fog(r)
        return r, r.render()

    def render_depth(
        self, world_from_cam: NDArray[np.float64], width: int, height: int, fov_deg: float
    ) -> NDArray[np.float32]:
        """(height, width) depth in metres along the optical axis of the view ``render`` draws
        from the optical-frame pose ``world_from_cam``: the scene's true geometry, e.g. to check a
        map's 3D points. The sky is at the far plane, ``FAR_M``."""
        r, _ = self._draw(world_from_cam, width, height, fov_deg)
        return _depth_m(r, width, height)

    def _cast_sun_shadows(self, scene: mujoco.MjvScene, aim_world: NDArray[np.float64]) -> None:
        """The sun casts shadows in a square around ``aim_world`` (3,). MuJoCo draws a
        shadow-casting light in a pass of its own, added where the light is not blocked, ambient
        included: the sky's ambient light moves to a light that casts none, or shadows go black."""
        lights = scene.lights[: scene.nlight]
        sun = next(light for light in lights if light.id == self.scene.sun_light_id)
        sun.castshadow = 1
        sun.pos[:] = aim_world - SHADOW_LIGHT_BACK_M * np.asarray(sun.dir)
        sky = scene.lights[scene.nlight]
        sky.id, sky.type, sky.headlight, sky.castshadow = -1, sun.type, 0, 0
        sky.dir[:] = [0.0, 0.0, -1.0]
        sky.diffuse[:] = sky.specular[:] = 0.0
        sky.ambient[:] = sun.ambient
        sun.ambient[:] = 0.0
        scene.nlight += 1

    def _add_lamps(self, scene: mujoco.MjvScene, aim_world: NDArray[np.float64]) -> None:
        """The street lamps nearest to ``aim_world`` (3,), as many as the frame has lights left:
        spot lights pointing down from the lamps' heads."""
        lamps = self.scene.town.lamps  # (N, 3): x, y, arm yaw
        free = MAX_FRAME_LIGHTS - scene.nlight
        if free <= 0 or len(lamps) == 0:
            return
        heads = lamps[:, :2] + LAMP_REACH_M * np.stack(
            [np.cos(lamps[:, 2]), np.sin(lamps[:, 2])], 1
        )
        nearest = np.argsort(np.hypot(*(heads - aim_world[:2]).T), kind="stable")[:free]
        for i in nearest:
            light = scene.lights[scene.nlight]
            light.type = mujoco.mjtLightType.mjLIGHT_SPOT
            light.headlight = 0
            light.castshadow = 0
            light.pos[:] = [*heads[i], LAMP_HEIGHT_M]
            light.dir[:] = [0.0, 0.0, -1.0]
            light.cutoff, light.exponent = 80.0, 1.0
            light.attenuation[:] = [0.0, 1.0, 0.0]  # 1/d: at the road under the head, lamp_level
            light.diffuse[:] = np.array([1.0, 0.9, 0.72]) * self.lamp_level * LAMP_HEIGHT_M
            light.ambient[:] = 0.0
            light.specular[:] = 0.1 * self.lamp_level
            scene.nlight += 1

    @staticmethod
    def _add_markers(
        scene: mujoco.MjvScene,
        points: NDArray[np.float64],
        radius: float,
        rgb: tuple[float, float, float],
    ) -> None:
        for p in points:
            if scene.ngeom >= scene.maxgeom:
                break
            g = scene.geoms[scene.ngeom]
            mujoco.mjv_initGeom(
                g,
                mujoco.mjtGeom.mjGEOM_SPHERE,
                np.array([radius, 0, 0]),
                np.asarray(p, float),
                np.eye(3).ravel(),
                np.array([*rgb, 1.0], np.float32),
            )
            g.emission = 1.0
            g.specular = 0.0
            scene.ngeom += 1

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()


def _depth_m(r: mujoco.Renderer, width: int, height: int) -> NDArray[np.float32]:
    """(height, width) depth in metres along the optical axis of ``r``'s last render."""
    depth = np.empty((height, width), np.float32)
    mujoco.mjr_readPixels(None, depth, r._rect, r._mjr_context)
    # reversed z, as MuJoCo's renderer keeps it: 1 at the near plane, 0 at the far one
    return (FAR_M * NEAR_M / ((FAR_M - NEAR_M) * np.flipud(depth) + NEAR_M)).astype(np.float32)


def _horizontal(direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """``direction`` (3,) projected onto the ground plane, unit length ((0, 0, 0) if vertical)."""
    flat = np.array([direction[0], direction[1], 0.0])
    norm = np.linalg.norm(flat)
    return flat / norm if norm > 1e-9 else flat
