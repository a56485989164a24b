"""2D graph SLAM: correlative + least-squares scan-to-submap matching (front end), loop closure and
sparse pose-graph optimization (back end), after Olson 2009 and Hess et al. 2016 (Cartographer).

Entry point: ``nav.slam.system.GraphSlam`` with ``nav.slam.system.SlamOptions``."""
