"""The ROS 2 side (the ``ros`` extra): the paper's localization node on vlocbench's localizer.

Nothing else in vlocbench imports this package. rclpy and the message packages come from PyPI
(``pip install 'vlocbench[ros]'``); :func:`vlocbench.ros.environment.local_only` keeps discovery on
this machine unless the user chose otherwise.
"""
