"""The LinkD model: curve encoder, causal DiT backbone and per-node diffusion head."""

from linkd.model.linkd import LinkD, LinkDConfig, load_checkpoint, save_checkpoint

__all__ = ["LinkD", "LinkDConfig", "load_checkpoint", "save_checkpoint"]
