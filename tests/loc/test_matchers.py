"""Mutual nearest neighbours with the ratio test, on real SIFT features of gallery images."""

import cv2
import numpy as np
import pytest

from vlocbench.loc.features import Features
from vlocbench.loc.matchers import MutualNearestNeighbor
from vlocbench.loc.registry import build_features


@pytest.fixture(scope="module")
def sift_features(gallery):
    extractor = build_features("opencv-sift")  # the most keypoints of our extractors
    return [extractor.extract(gallery.load_image(gallery.names[k])) for k in (10, 11, 12)]


def _reference(a: Features, b: Features, ratio: float) -> set[tuple[int, int]]:
    """The definition, in float64: a's nearest b within ratio x the second nearest, mutual."""
    d = np.linalg.norm(a.descriptors[:, None].astype(np.float64) - b.descriptors[None], axis=2)
    order = np.argsort(d, axis=1)
    rows = np.arange(len(a))
    first, second = d[rows, order[:, 0]], d[rows, order[:, 1]]
    mutual = d.argmin(0)[order[:, 0]] == rows
    keep = (first < ratio * second) & mutual
    return {(int(i), int(order[i, 0])) for i in rows[keep]}


def test_l2_matches_are_the_definitions_and_opencvs(sift_features):
    matcher = MutualNearestNeighbor(ratio=0.8)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    for a, b in ((sift_features[0], sift_features[1]), (sift_features[1], sift_features[2])):
        ours = {tuple(m) for m in matcher.match(a, b).tolist()}
        assert len(ours) > 50
        assert ours == _reference(a, b, 0.8)
        forward = bf.knnMatch(a.descriptors, b.descriptors, k=2)
        backward = {m.queryIdx: m.trainIdx for m in bf.match(b.descriptors, a.descriptors)}
        opencv = {
            (i, f[0].trainIdx)
            for i, f in enumerate(forward)
            if f[0].distance < 0.8 * f[1].distance and backward[f[0].trainIdx] == i
        }
        assert len(ours ^ opencv) <= 0.002 * len(ours)  # rounding at the ratio test's edge


def test_too_few_features_match_nothing(sift_features):
    one = sift_features[0].subset(np.arange(1))
    assert MutualNearestNeighbor().match(one, sift_features[1]).shape == (0, 2)
    assert MutualNearestNeighbor().match(sift_features[1], one).shape == (0, 2)


def test_binary_descriptors_match_by_hamming_distance(gallery):
    extractor = build_features("orb-teblid")
    a, b = (extractor.extract(gallery.load_image(gallery.names[k])) for k in (20, 21))
    matches = MutualNearestNeighbor(hamming=True).match(a, b)
    # 39 on scene 7's small town (its walls changed), more than 50 before
    assert len(matches) > 30 and len(np.unique(matches[:, 1])) == len(matches)
