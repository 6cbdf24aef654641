"""Pearl POMDP: a hierarchical POMDP behaviour manager for ROS 2 service robots.

The core (everything but :mod:`pearl_pomdp.nodes`) imports no ROS and can be used
as a plain Python library.
"""
from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("pearl_pomdp")
except _metadata.PackageNotFoundError:  # running from a source tree without install
    __version__ = "0+unknown"
