import matplotlib.image as mpimg

from vlocbench.bench import EpisodeConfig, plan_town_route, run_episode
from vlocbench.bench.plots import save_episode_map
from vlocbench.nav import OdometryNoise
from vlocbench.sim import Simulator


def test_episode_map_is_written(small_town, tmp_path):
    with Simulator(small_town) as sim:
        path = plan_town_route(small_town)
        noisy = EpisodeConfig(seed=2, odometry=OdometryNoise(0.04, 0.1, 0.3))
        episodes = {
            "ground truth": run_episode(sim, path, None, EpisodeConfig(mode="ground_truth")),
            "odometry": run_episode(sim, path, None, noisy),
        }
    assert episodes["odometry"].failures >= 1
    png = save_episode_map(small_town, episodes, tmp_path / "drive.png")
    image = mpimg.imread(png)
    assert image.shape[0] > 300 and image.shape[1] > 300
