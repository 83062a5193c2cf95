"""A user's own feature extractor, loaded by dotted path in the tests (no change to the package)."""

from vlocbench.loc.features import SiftExtractor


class CountingSift(SiftExtractor):
    calls = 0

    def __init__(self) -> None:
        super().__init__(max_keypoints=1024, name="counting-sift")

    def extract(self, image):
        CountingSift.calls += 1
        return super().extract(image)


class NotAnExtractor:
    name = "nothing"
