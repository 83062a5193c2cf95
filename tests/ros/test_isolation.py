"""The ROS tests' isolation from other test processes on the same machine."""

import subprocess
import sys

from tests.ros.conftest import domain_lock

_TRY_LOCK = "import fcntl, sys; fcntl.flock(open(sys.argv[1], 'a'), fcntl.LOCK_EX | fcntl.LOCK_NB)"


def test_another_test_process_cannot_take_this_ones_ros_domain(ros_domain):
    lock = domain_lock(ros_domain)
    taken = subprocess.run([sys.executable, "-c", _TRY_LOCK, str(lock)], capture_output=True)
    assert taken.returncode != 0 and b"BlockingIOError" in taken.stderr
