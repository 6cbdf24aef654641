"""Pearl POMDP: a hierarchical POMDP behaviour manager for ROS 2 service robots.

The core (everything but :mod:`pearl_pomdp.nodes`) imports no ROS and can be used
as a plain Python library.
"""


def __getattr__(name: str):
    # ``__version__`` is looked up on first use: importlib.metadata costs ~20 ms of start-up
    # that every node and command would otherwise pay before doing anything.
    if name == "__version__":
        from importlib import metadata

        try:
            version = metadata.version("pearl_pomdp")
        except metadata.PackageNotFoundError:  # running from a source tree without install
            version = "0+unknown"
        globals()["__version__"] = version
        return version
    raise AttributeError(f"module 'pearl_pomdp' has no attribute {name!r}")
