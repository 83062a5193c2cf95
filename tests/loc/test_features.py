import numpy as np

from vlocbench.loc.features import SHARED_IMAGES, extract_timed, shared_extraction
from vlocbench.loc.registry import build_features


class Counting:
    """An extractor that counts its extractions."""

    name, binary = "counting", False

    def __init__(self):
        self.inner, self.calls = build_features("opencv-sift"), 0

    def extract(self, image):
        self.calls += 1
        return self.inner.extract(image)


def test_shared_extraction_extracts_an_image_once_per_preset():
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 255, (120, 160, 3), np.uint8) for _ in range(SHARED_IMAGES + 1)]
    ex = Counting()
    alone = [extract_timed(ex, "a", images[0]) for _ in range(2)]
    assert ex.calls == 2 and all(shared == 0 for _, _, shared in alone)
    with shared_extraction():
        first, seconds, shared = extract_timed(ex, "a", images[0])
        again = extract_timed(ex, "a", images[0].copy())  # the same pixels in another array
        other_preset = extract_timed(ex, "b", images[0])
        assert ex.calls == 4 and shared == 0 and other_preset[2] == 0
        # the features of the first extraction, and its seconds, charged to the second caller
        assert again[0] is first and again[1] == again[2] == seconds > 0
        for image in images[1:]:  # the oldest goes once more images were seen
            extract_timed(ex, "b", image)
        extract_timed(ex, "a", images[0])
        assert ex.calls == 4 + SHARED_IMAGES + 1
    np.testing.assert_array_equal(first.keypoints, alone[0][0].keypoints)
    extract_timed(ex, "a", images[0])  # outside, nothing is kept
    assert ex.calls == 4 + SHARED_IMAGES + 2
