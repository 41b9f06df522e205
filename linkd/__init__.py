"""linkd: from a target curve to a verified planar linkage (LinkD method)."""

__version__ = "0.1.0"
