"""The methods bomgraph compares BOM-STMDS against: EKF-SLAM, GTSAM smoothers, the hybrid.

Each is a :class:`bomgraph.mapper.Mapper`; ``bomgraph`` names them in its registry and imports
them only on use. ``baselines`` imports ``bomgraph``, never the reverse.
"""
