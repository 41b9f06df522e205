"""LinkD: curve encoder + causal transformer + per-node DDPM head, trained by teacher forcing.

The head diffuses a node's 24 entries in a symmetric form: the binary entries (validity,
ground, links) as -1 / +1 and the position as it is. Link entries to joints j >= t do not
exist for node t: they are zeroed in the head's input, ignored by the loss and decoded as -1.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from linkd.graph import ADJ, FEATURES, MAX_NODES, TYPE, VALID, XY
from linkd.model.backbone import CausalBackbone
from linkd.model.diffusion import DenoiseUNet, cosine_alpha_bar, ddim_sample
from linkd.model.encoder import CurveEncoder
from linkd.model.frame import principal_turn, turned

BINARY = torch.tensor([k not in (2, 3) for k in range(FEATURES)])


@dataclass
class LinkDConfig:
    dim: int = 128
    layers: int = 4
    heads: int = 4
    encoder_layers: int = 2
    cross_attention: bool = False  # nodes also attend to the curve's patch tokens (not in paper)
    head_widths: tuple[int, ...] = (128, 64, 32)
    head_cond: int = 64  # width of the (context + timestep) vector that FiLMs the head
    diffusion_steps: int = 1000
    sample_steps: int = 10  # default DDIM steps at inference
    sample_eta: float = 0.0  # DDIM stochasticity at inference (0: deterministic given noise)
    link_weight: float = 1.0  # BCE weight of present links; above 1 biases x0 towards links
    position_weight: float = 2.0
    huber_beta: float = 0.05
    curve_dropout: float = 0.0  # training: share of graphs shown the null curve (for guidance)
    guidance: float = 1.0  # default classifier-free guidance scale at inference (1: none)
    sample_coins: bool = True  # draw validity and type as coins (False: deterministic DDIM)
    sample_dyadic: bool = False  # decode a joint's links as a dyad's (`to_rows`): more valid
    # one-shot samples, but farther from their curves, and worse proposals for `linkd design`
    canonical: bool = False  # read curves and place joints in the curve's principal frame


def link_mask(index: torch.Tensor) -> torch.Tensor:
    """(M, MAX_NODES) True where node `index` may link: earlier joints j < index."""
    return torch.arange(MAX_NODES, device=index.device)[None] < index[:, None]


def to_target(rows: torch.Tensor) -> torch.Tensor:
    """Graph-matrix rows -> the diffused form: binary entries +-1, positions (0 for padding)."""
    target = (rows == 1).to(rows.dtype) * 2 - 1
    target[..., XY] = rows[..., XY] * (rows[..., VALID : VALID + 1] > 0.5)
    return target


def to_rows(x0: torch.Tensor, index: torch.Tensor, dyadic: bool = False) -> torch.Tensor:
    """Clean estimates (M, 24) of nodes `index` (M,) -> decoded graph-matrix rows.

    dyadic: a joint's links as a dyad has them, the way every valid graph is built: a moving
    joint gets its two likeliest links to earlier joints (the crank tip its one, to the pivot),
    a ground joint none. Otherwise each link is kept where its estimate is positive.
    """
    valid = x0[:, VALID] > 0
    ground = x0[:, TYPE] > 0
    rows = torch.full_like(x0, -1.0)
    rows[:, VALID] = valid.to(x0.dtype)
    rows[:, TYPE] = torch.where(valid, ground.to(x0.dtype), -1.0)
    rows[:, XY] = torch.where(valid[:, None], x0[:, XY].clamp(-1, 1), 0.0)
    earlier = link_mask(index)
    if dyadic:
        score = x0[:, ADJ].masked_fill(~earlier, -torch.inf)
        rank = score.argsort(dim=1, descending=True, stable=True).argsort(dim=1)
        wanted = torch.where(ground, 0, index.clamp(max=2))
        links = (rank < wanted[:, None]).to(x0.dtype)
    else:
        links = (x0[:, ADJ] > 0).to(x0.dtype)
    rows[:, ADJ] = torch.where(valid[:, None] & earlier, links, -1.0)
    return rows


class LinkD(nn.Module):
    def __init__(self, config: LinkDConfig) -> None:
        super().__init__()
        self.config = config
        c = config
        self.encoder = CurveEncoder(c.dim, c.encoder_layers, c.heads)
        self.backbone = CausalBackbone(c.dim, c.layers, c.heads, c.cross_attention)
        self.head = DenoiseUNet(FEATURES, c.dim, tuple(c.head_widths), c.head_cond)
        self.null_curve = nn.Parameter(torch.zeros(1, 1, c.dim))  # "no curve", for guidance
        self.register_buffer("alpha_bar", cosine_alpha_bar(c.diffusion_steps), persistent=False)
        self.register_buffer("binary", BINARY.clone(), persistent=False)

    def clean_estimate(self, out: torch.Tensor) -> torch.Tensor:
        """Head output -> x_0 estimate: tanh(logit / 2) = 2p - 1 for binary entries."""
        return torch.where(self.binary, torch.tanh(out / 2), out.clamp(-1, 1))

    def head_input(self, x_t: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        keep = torch.ones_like(x_t, dtype=torch.bool)
        keep[:, ADJ] = link_mask(index)
        return x_t * keep

    def forward(
        self, graphs: torch.Tensor, curves: torch.Tensor, draws: int = 4
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Teacher-forced loss of (B, 20, 24) graphs given (B, 200, 2) curves.

        Every valid node and the first padding row (the stop signal) is a target; each is
        noised at `draws` random timesteps (the head is cheap next to the transformer). A
        canonical model first turns graph and curve into the curve's principal frame.
        """
        c = self.config
        if c.canonical:
            turn = principal_turn(curves)
            graphs, curves = turned(graphs, turn), curves @ turn.transpose(1, 2)
        cond = self.encoder(curves)
        if self.training:  # (always in the graph, so every rank's DDP sees the parameter)
            drop = torch.rand(len(cond), device=cond.device) < c.curve_dropout
            cond = torch.where(drop[:, None, None], self.null_curve.to(cond.dtype), cond)
        h = self.backbone(graphs[:, :-1], cond)
        valid = graphs[..., VALID] > 0.5
        before = torch.cat([torch.ones_like(valid[:, :1]), valid[:, :-1]], 1)
        active = before.cumprod(1).bool()
        index = torch.arange(valid.shape[1], device=graphs.device).expand_as(valid)[active]
        index = index.repeat(draws)
        context = h[active].repeat(draws, 1)
        x0 = to_target(graphs[active]).repeat(draws, 1)
        is_valid = valid[active].repeat(draws)
        t = torch.randint(0, c.diffusion_steps, (len(x0),), device=graphs.device)
        a = self.alpha_bar[t][:, None]
        x_t = a.sqrt() * x0 + (1 - a).sqrt() * torch.randn_like(x0)
        out = self.head(self.head_input(x_t, index), t, context)

        target01 = (x0 > 0).to(x0.dtype)
        parts = {"validity": F.binary_cross_entropy_with_logits(out[:, VALID], target01[:, VALID])}
        v = is_valid
        parts["type"] = F.binary_cross_entropy_with_logits(out[v, TYPE], target01[v, TYPE])
        parts["position"] = F.smooth_l1_loss(out[v, XY], x0[v, XY], beta=c.huber_beta)
        links = link_mask(index[v])
        weight = torch.where(target01[v, ADJ] > 0, c.link_weight, 1.0)[links]
        parts["links"] = F.binary_cross_entropy_with_logits(
            out[v, ADJ][links], target01[v, ADJ][links], weight=weight
        )
        total = (
            parts["validity"]
            + parts["type"]
            + parts["links"]
            + c.position_weight * parts["position"]
        )
        return total, {k: val.detach() for k, val in parts.items()}

    def encode(self, curves: torch.Tensor) -> torch.Tensor:
        """(B, 200, 2) curves -> (B, 1 + P, dim): E(C) then the curve's patch tokens."""
        return self.encoder(curves)

    def null_encoding(self, like: torch.Tensor) -> torch.Tensor:
        """The encoding of "no curve", shaped like a batch of curve encodings."""
        return self.null_curve.to(like.dtype).expand_as(like)

    def new_cache(self) -> list[dict]:
        return [{} for _ in self.backbone.blocks]

    @torch.no_grad()
    def denoise(
        self,
        context: torch.Tensor,
        index: torch.Tensor,
        steps: int | None = None,
        generator: torch.Generator | None = None,
        null_context: torch.Tensor | None = None,
        guidance: float | None = None,
    ) -> torch.Tensor:
        """Sample decoded rows (M, 24) for nodes `index` (M,) from their contexts (M, dim).

        With `null_context` (the same nodes' contexts given no curve), the head's outputs are
        pushed away from the unconditional ones by the guidance scale (classifier-free
        guidance). Validity and type are drawn as coins from the head's first, pure-noise
        estimate and then held: deterministic DDIM would otherwise always take the likelier
        side, and graphs would never stop or gain ground joints as often as the data does.
        """
        c = self.config
        w = c.guidance if guidance is None else guidance
        noise = torch.randn(
            (len(context), FEATURES), generator=generator, device=context.device
        ).to(context.dtype)
        held = torch.zeros(FEATURES, dtype=torch.bool, device=context.device)
        held[[VALID, TYPE]] = True
        coins: list[torch.Tensor] = []

        def predict(x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
            x_in = self.head_input(x_t, index)
            if null_context is not None and w != 1.0:  # both passes as one batch
                both = self.head(x_in.repeat(2, 1), t.repeat(2), torch.cat([context, null_context]))
                out, null = both.chunk(2)
                out = out + (w - 1.0) * (out - null)
            else:
                out = self.head(x_in, t, context)
            x0 = self.clean_estimate(out)
            if not c.sample_coins:
                return x0
            if not coins:  # first step: draw validity and type with the predicted odds
                p = (x0[:, held] + 1) / 2
                u = torch.rand(p.shape, generator=generator, device=p.device).to(p.dtype)
                coins.append((u < p).to(x0.dtype) * 2 - 1)
            return _hold(x0, held, coins[0])

        x0 = ddim_sample(predict, noise, self.alpha_bar, steps or c.sample_steps, c.sample_eta,
                         generator)  # fmt: skip
        return to_rows(x0, index, c.sample_dyadic)


def _hold(x0: torch.Tensor, held: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """x0 with the `held` entries replaced by `values` (M, held.sum())."""
    x0 = x0.clone()
    x0[:, held] = values
    return x0


def save_checkpoint(path: str | Path, model: LinkD, **extra: object) -> None:
    """Model config and weights (plus anything in `extra`, e.g. optimiser state) in one file."""
    state = {"config": asdict(model.config), "model": model.state_dict(), **extra}
    torch.save(state, Path(path))


def load_checkpoint(path: str | Path, device: str = "cpu") -> tuple[LinkD, dict]:
    """The model of a checkpoint (in eval mode) and the raw checkpoint dictionary."""
    state = torch.load(Path(path), map_location=device, weights_only=True)
    config = dict(state["config"])
    config["head_widths"] = tuple(config["head_widths"])
    model = LinkD(LinkDConfig(**config)).to(device)
    weights = dict(state["model"])
    weights.setdefault("null_curve", model.null_curve.detach())  # trained before guidance
    model.load_state_dict(weights)
    return model.eval(), state
