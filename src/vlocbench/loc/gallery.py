"""Galleries: images with exact camera poses, in a simple folder format anyone can write.

Layout::

    GALLERY/
      gallery.json   {"version": 1, "cameras": {NAME: {"width", "height", "K"}},
                      "images": [{"name", "camera", "world_from_cam"}, ...]}
      images/NAME    the images (PNG or JPEG), RGB

``K`` is the 3x3 calibration matrix in OpenCV's convention (pixel centres at integers);
``world_from_cam`` is a 4x4 row-major pose of the OpenCV camera frame (x right, y down, z forward)
in the world frame (metres).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from vlocbench.errors import LocalizationError
from vlocbench.interfaces import Array
from vlocbench.loc.features import check_image

GALLERY_FILE = "gallery.json"
IMAGE_DIR = "images"


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera: image size in pixels and ``K`` (3, 3), OpenCV convention."""

    width: int
    height: int
    K: Array

    @property
    def fov_deg(self) -> float:
        """The horizontal field of view of a pinhole camera centred on its image, in degrees."""
        return float(np.degrees(2 * np.arctan(self.width / (2 * self.K[0, 0]))))

    def to_json(self) -> dict:
        return {"width": self.width, "height": self.height, "K": np.asarray(self.K).tolist()}

    @classmethod
    def from_json(cls, data: dict, field: str) -> CameraModel:
        try:
            K = np.asarray(data["K"], dtype=np.float64)
            width, height = int(data["width"]), int(data["height"])
        except (KeyError, TypeError, ValueError) as exc:
            raise LocalizationError(f"{field}: needs width, height and K ({exc})") from None
        if K.shape != (3, 3) or width <= 0 or height <= 0 or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise LocalizationError(f"{field}: K must be 3x3 with positive focal lengths")
        return cls(width, height, K)


@dataclass(frozen=True)
class GalleryImage:
    name: str
    camera: str
    world_from_cam: Array  # (4, 4)


class Gallery:
    """A gallery folder: its cameras, its images' names and poses; images load on demand."""

    def __init__(self, root: Path, cameras: dict[str, CameraModel], images: list[GalleryImage]):
        self.root = root
        self.cameras = cameras
        self.images = images
        self._index = {im.name: k for k, im in enumerate(images)}

    def __len__(self) -> int:
        return len(self.images)

    @property
    def names(self) -> list[str]:
        return [im.name for im in self.images]

    def index_of(self, name: str) -> int:
        return self._index[name]

    def load_image(self, name: str) -> NDArray[np.uint8]:
        """(H, W, 3) RGB."""
        path = self.root / IMAGE_DIR / name
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise LocalizationError(f"gallery image {path} is missing or unreadable")
        return check_image(bgr[:, :, ::-1], f"gallery image {path}")

    def head(self, count: int, root: str | Path) -> Gallery:
        """Its first ``count`` images as a gallery of their own in ``root`` (the files copied as
        they are): a stretch of a route, for a quick map."""
        writer = GalleryWriter(root)
        for im in self.images[:count]:
            source = self.root / IMAGE_DIR / im.name
            writer.add_file(im.name, source, im.camera, self.cameras[im.camera], im.world_from_cam)
        return writer.close()

    @property
    def identity(self) -> str:
        """What keys maps built from this gallery: its folder name and the content of its index."""
        import hashlib

        text = (self.root / GALLERY_FILE).read_bytes()
        return f"{self.root.name}-{hashlib.sha256(text).hexdigest()[:10]}"

    @classmethod
    def load(cls, root: str | Path) -> Gallery:
        root = Path(root)
        path = root / GALLERY_FILE
        if not path.is_file():
            raise LocalizationError(f"{root} is not a gallery: {GALLERY_FILE} is missing")
        try:
            data = json.loads(path.read_text())
            cameras = {
                name: CameraModel.from_json(c, f"{path}: cameras.{name}")
                for name, c in data["cameras"].items()
            }
            images = []
            for k, im in enumerate(data["images"]):
                pose = np.asarray(im["world_from_cam"], dtype=np.float64)
                if pose.shape != (4, 4) or not np.allclose(pose[3], [0, 0, 0, 1]):
                    raise LocalizationError(f"{path}: images[{k}].world_from_cam is not a 4x4 pose")
                if im["camera"] not in cameras:
                    raise LocalizationError(
                        f"{path}: images[{k}].camera {im['camera']!r} is not one of "
                        f"{sorted(cameras)}"
                    )
                images.append(GalleryImage(str(im["name"]), str(im["camera"]), pose))
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            raise LocalizationError(f"{path} is corrupt: {exc!r}") from None
        if not images:
            raise LocalizationError(f"gallery {root} has no images")
        return cls(root, cameras, images)


class GalleryWriter:
    """Adds images to a new gallery folder; ``close()`` writes the index (atomically)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        (self.root / IMAGE_DIR).mkdir(parents=True, exist_ok=True)
        self.cameras: dict[str, CameraModel] = {}
        self.images: list[GalleryImage] = []

    def add(
        self,
        name: str,
        image: NDArray[np.uint8],
        camera_name: str,
        camera: CameraModel,
        world_from_cam: Array,
    ) -> None:
        path = self._image_path(name, camera_name, camera, world_from_cam)
        cv2.imwrite(str(path), np.ascontiguousarray(image[:, :, ::-1]))

    def add_file(
        self, name: str, source: Path, camera_name: str, camera: CameraModel, world_from_cam: Array
    ) -> None:
        """Add the image file ``source`` as it is (no re-encoding), once its size is checked."""
        image = cv2.imread(str(source), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise LocalizationError(f"{source} is not a readable image")
        if image.shape[:2] != (camera.height, camera.width):
            raise LocalizationError(
                f"{source} is {image.shape[1]}x{image.shape[0]}, its camera "
                f"{camera.width}x{camera.height}"
            )
        shutil.copyfile(source, self._image_path(name, camera_name, camera, world_from_cam))

    def _image_path(
        self, name: str, camera_name: str, camera: CameraModel, world_from_cam: Array
    ) -> Path:
        """Record the image; where its file goes (folders in its name are made)."""
        known = self.cameras.setdefault(camera_name, camera)
        if known.width != camera.width or not np.allclose(known.K, camera.K):
            raise LocalizationError(f"camera {camera_name!r} changed its calibration")
        self.images.append(
            GalleryImage(name, camera_name, np.asarray(world_from_cam, dtype=np.float64))
        )
        path = self.root / IMAGE_DIR / name
        path.parent.mkdir(parents=True, exist_ok=True)
        return path

    def close(self) -> Gallery:
        data = {
            "version": 1,
            "cameras": {n: c.to_json() for n, c in self.cameras.items()},
            "images": [
                {"name": im.name, "camera": im.camera, "world_from_cam": im.world_from_cam.tolist()}
                for im in self.images
            ],
        }
        tmp = self.root / (GALLERY_FILE + ".tmp")
        tmp.write_text(json.dumps(data, indent=1))
        tmp.replace(self.root / GALLERY_FILE)
        return Gallery.load(self.root)
