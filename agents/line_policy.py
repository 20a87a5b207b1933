"""A per-section, permutation-equivariant actor-critic for TampingLine, as an SB3 policy.

Why this shape. The line's sections are alike (the same physics, the same costs) and what differs between
them is in their observation (measured SD and peak, register, tamping history). So one small network scores
every section with shared weights — the policy learns one rule for a section, not twelve — and the same
weights run on a line of any length (the small, default and hard scenarios: 6, 12 and 24 sections). A campaign
is one possession for all its sections (its cost is shared), so each section also sees a pooled summary of the
whole line (mean and max of the section embeddings): "a campaign is called anyway, join it" is expressible, as
in the best rule (grouped-threshold).

The network (a Deep Sets encoder with one round of pooling; ``H`` = ``hidden``):

* **features** (:func:`section_features`): per section ``F`` = 13 numbers, each observation key divided by a
  fixed scale of :data:`FEATURE_SCALES` (mm, years, counts; fixed rather than VecNormalize statistics, so that
  the policy does not depend on the line it was trained on) and clipped to [0, :data:`FEATURE_CLIP`]:
  measured SD, measured peak, register one-hot (3), tampings, tampings since renewal, years since tamping,
  and the line's globals broadcast to every section (measurement age, time, budget left, and the line's worst
  and mean measured SD: a campaign is called on the worst section, and a sharp threshold on an input is one
  unit, where the same threshold on the pooled embeddings was learnt only to ~0.1 mm — the clone's
  disagreements with the rule sat there);
* **encoder** φ: ``F → H → H`` per section, ``h_i = φ(x_i)``; context ``c = [mean_i h_i, max_i h_i]``;
* **actor**: per section ``[h_i, c] → H``, then one logit (:class:`SectionHead`): the probability of tamping
  section ``i`` — SB3's MultiBinary (Bernoulli) distribution, or with MaskablePPO the pair (0, logit) per
  section of sb3-contrib's masked MultiBinary distribution (the same Bernoulli; masked sections get none);
* **critic**: ``c → H → 1``, invariant to the order of the sections.

Permuting the sections permutes the logits and leaves the value unchanged (tested). Rewards are scaled by the
trainer (:mod:`trackenv_agents.train_line`) per section, so the value — a mean over sections — is O(1) on
every line length.

:class:`LineAgent` wraps a trained policy with SB3's ``predict`` on raw observations of a line of any length,
the interface of the evaluation harness and the heuristics.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from .heuristics import _as_batch

__all__ = ["FEATURE_CLIP", "FEATURE_SCALES", "N_FEATURES", "LineAgent", "MaskableSectionActorCritic",
           "SectionActorCritic", "SectionFeatures", "SectionHead", "SectionNet", "section_features",
           "section_policy_class"]

#: Fixed scale of each observation key (the feature is value / scale), chosen so that typical values are O(1):
#: SD 2 mm (between the rules' inclusion and trigger SDs; alert ~1.5-3 mm), peak 5 mm, tampings in an
#: episode 4, tampings since renewal 8 (renewal at the 8th), years since tamping 4, measurement age half a
#: year (one recording interval); time and budget are already fractions.
FEATURE_SCALES: dict[str, float] = {
    "section_sd": 2.0, "section_peak": 5.0, "tampings": 4.0, "tampings_since_renewal": 8.0,
    "years_since_tamping": 4.0, "measurement_age": 0.5, "time": 1.0, "budget_left": 1.0,
}
#: Scaled features are clipped to [0, FEATURE_CLIP]: typical values are O(1), and a rare extreme (a hidden wet
#: spot at 19 mm of SD, a section untended for 12 years) must not drive the network far beyond its training
#: data — a clone without the clip tamped every section of a line whose worst SD was 19 mm, where the rule
#: tamped the four above its inclusion SD. (VecNormalize's ``clip_obs`` does the same in standard deviations.)
FEATURE_CLIP = 4.0
_PER_SECTION = ("section_sd", "section_peak", "tampings", "tampings_since_renewal", "years_since_tamping")
_GLOBAL = ("measurement_age", "time", "budget_left")
N_REGISTER = 3  # plain, transition zone, switch or crossing (trackenv.envs.line_config.REGISTER_CLASSES)
N_LINE = 2  # the line's worst and mean measured SD (scaled like section_sd)
N_FEATURES = len(_PER_SECTION) + N_REGISTER + len(_GLOBAL) + N_LINE


def _check_scales(scales: Mapping[str, float]) -> dict[str, float]:
    out = {k: float(v) for k, v in scales.items()}
    missing = set(FEATURE_SCALES) - set(out)
    if missing or set(out) - set(FEATURE_SCALES):
        raise ValueError(f"feature_scales must have exactly the keys {sorted(FEATURE_SCALES)}, got {sorted(out)}")
    bad = {k: v for k, v in out.items() if not (np.isfinite(v) and v > 0)}
    if bad:
        raise ValueError(f"feature_scales must be finite and > 0, got {bad}")
    return out


def section_features(obs: Mapping[str, torch.Tensor], scales: Mapping[str, float] = FEATURE_SCALES) -> torch.Tensor:
    """(batch, S, :data:`N_FEATURES`) per-section features of a batched TampingLine observation (tensors)."""
    per = torch.stack([obs[k].float() / scales[k] for k in _PER_SECTION], dim=-1).clamp(0.0, FEATURE_CLIP)
    S = per.shape[1]
    register = nn.functional.one_hot(obs["register"].round().long().clamp(0, N_REGISTER - 1), N_REGISTER)
    sd = per[..., 0]
    glob = torch.cat([*(obs[k].float().reshape(-1, 1) / scales[k] for k in _GLOBAL)], dim=-1).clamp(0.0, FEATURE_CLIP)
    glob = torch.cat([glob, sd.amax(dim=1, keepdim=True), sd.mean(dim=1, keepdim=True)], dim=-1)  # (B, 5)
    return torch.cat([per, register.float(), glob[:, None, :].expand(-1, S, -1)], dim=-1)


class SectionFeatures(BaseFeaturesExtractor):
    """SB3 features extractor: the (batch, S, F) tensor of :func:`section_features`. Its nominal
    ``features_dim`` (S·F of the space it was built for) is not used: :class:`SectionNet` reads any S."""

    def __init__(self, observation_space: spaces.Dict, scales: Mapping[str, float] = FEATURE_SCALES) -> None:
        super().__init__(observation_space, features_dim=observation_space["section_sd"].shape[0] * N_FEATURES)
        self.scales = _check_scales(scales)

    def forward(self, observations: Mapping[str, torch.Tensor]) -> torch.Tensor:
        return section_features(observations, self.scales)


class SectionNet(nn.Module):
    """The shared encoder, the per-section actor and the pooled critic (the module docstring's φ, actor,
    critic), in SB3's ``mlp_extractor`` interface: ``forward_actor`` → (batch, S, H) per-section latents,
    ``forward_critic`` → (batch, H)."""

    def __init__(self, hidden: int = 32, activation_fn: type[nn.Module] = nn.Tanh) -> None:
        super().__init__()
        H = int(hidden)
        self.encoder = nn.Sequential(nn.Linear(N_FEATURES, H), activation_fn(), nn.Linear(H, H), activation_fn())
        self.actor = nn.Sequential(nn.Linear(3 * H, H), activation_fn())
        self.critic = nn.Sequential(nn.Linear(2 * H, H), activation_fn())
        self.latent_dim_pi = H
        self.latent_dim_vf = H

    def _encode(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.encoder(features)
        return h, torch.cat([h.mean(dim=1), h.amax(dim=1)], dim=-1)

    def _actor(self, h: torch.Tensor, context: torch.Tensor) -> torch.Tensor:
        return self.actor(torch.cat([h, context[:, None, :].expand(-1, h.shape[1], -1)], dim=-1))

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h, context = self._encode(features)
        return self._actor(h, context), self.critic(context)

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        return self._actor(*self._encode(features))

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        return self.critic(self._encode(features)[1])


class SectionHead(nn.Module):
    """One logit per section from its latent (a shared ``Linear(H, 1)``), in the layout the action
    distribution wants: (batch, S) for SB3's Bernoulli, or (batch, 2·S) pairs (0, logit) for sb3-contrib's
    masked MultiBinary (``paired``). ``bias`` is the initial log-odds of tamping (settable, as
    :func:`trackenv_agents.train._set_initial_tamp_logit` does)."""

    def __init__(self, hidden: int, paired: bool = False) -> None:
        super().__init__()
        self.linear = nn.Linear(int(hidden), 1)
        self.paired = bool(paired)

    @property
    def bias(self) -> torch.Tensor:
        return self.linear.bias

    def logits(self, latent: torch.Tensor) -> torch.Tensor:
        return self.linear(latent).squeeze(-1)

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        logit = self.logits(latent)
        if self.paired:
            return torch.stack([torch.zeros_like(logit), logit], dim=-1).flatten(1)
        return logit


class _SectionPolicyMixin:
    """What turns an SB3 actor-critic policy into the per-section one: the features extractor, the
    ``mlp_extractor`` (:class:`SectionNet`) and the action head (:class:`SectionHead`)."""

    _paired = False

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.MultiBinary, lr_schedule: Any,
                 hidden: int = 32, feature_scales: Mapping[str, float] | None = None, **kwargs: Any) -> None:
        if not isinstance(hidden, (int, np.integer)) or not 1 <= hidden <= 1024:
            raise ValueError(f"hidden must be an integer in [1, 1024], got {hidden!r}")
        if not isinstance(action_space, spaces.MultiBinary):
            raise ValueError(f"the per-section policy needs a MultiBinary action space, got {action_space}")
        self.hidden = int(hidden)
        self.feature_scales = _check_scales(FEATURE_SCALES if feature_scales is None else feature_scales)
        kwargs["features_extractor_class"] = SectionFeatures
        kwargs["features_extractor_kwargs"] = {"scales": self.feature_scales}
        kwargs.pop("net_arch", None)  # the architecture is SectionNet's
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)  # type: ignore[call-arg]

    def _build_mlp_extractor(self) -> None:
        self.mlp_extractor = SectionNet(self.hidden, self.activation_fn)  # type: ignore[attr-defined]

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)  # type: ignore[misc]
        # SB3 built a Linear(H, n_actions) head; the shared per-section one replaces it (with SB3's small
        # initial gain), and the optimiser is rebuilt over the final parameters
        self.action_net = SectionHead(self.hidden, paired=self._paired)
        if self.ortho_init:  # type: ignore[attr-defined]
            nn.init.orthogonal_(self.action_net.linear.weight, gain=0.01)
            nn.init.zeros_(self.action_net.linear.bias)
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1),  # type: ignore[attr-defined]
                                              **self.optimizer_kwargs)  # type: ignore[attr-defined]

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()  # type: ignore[misc]
        data.update(hidden=self.hidden, feature_scales=dict(self.feature_scales))
        data.pop("net_arch", None)
        return data

    def section_logits(self, obs: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """(batch, S) log-odds of tamping each section, for a line of any length S."""
        features = self.pi_features_extractor(obs)  # type: ignore[attr-defined]
        return self.action_net.logits(self.mlp_extractor.forward_actor(features))  # type: ignore[attr-defined]

    def section_value(self, obs: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """(batch,) value, for a line of any length S."""
        features = self.vf_features_extractor(obs)  # type: ignore[attr-defined]
        return self.value_net(self.mlp_extractor.forward_critic(features)).squeeze(-1)  # type: ignore[attr-defined]


class SectionActorCritic(_SectionPolicyMixin, ActorCriticPolicy):
    """The per-section actor-critic for SB3's PPO (MultiBinary: one Bernoulli per section)."""


class MaskableSectionActorCritic(_SectionPolicyMixin, MaskableActorCriticPolicy):
    """The per-section actor-critic for sb3-contrib's MaskablePPO: the env's masks (a section tamped in the
    last ``min_steps_between_tampings`` steps) remove the tamp choice of a section, so no update credits a
    tamping the env would drop."""

    _paired = True


def section_policy_class(algo: str) -> type[ActorCriticPolicy]:
    """The policy class for ``algo`` ("ppo" or "maskable_ppo")."""
    classes = {"ppo": SectionActorCritic, "maskable_ppo": MaskableSectionActorCritic}
    if algo not in classes:
        raise ValueError(f"algo must be one of {sorted(classes)}, got {algo!r}")
    return classes[algo]


class LineAgent:
    """A trained per-section policy with SB3's ``predict(obs, state=None, episode_start=None,
    deterministic=True) -> (action, state)`` on raw TampingLine observations (one dict, or a batched one) of
    a line of any length: int8 0/1 per section. Deterministic: tamp where the logit is > 0 (the Bernoulli's
    mode); otherwise a draw from ``rng`` (a numpy Generator; None: a fresh unseeded one)."""

    def __init__(self, policy: _SectionPolicyMixin, name: str = "ppo", rng: np.random.Generator | None = None) -> None:
        self.policy = policy
        self.name = name
        self.params: dict[str, Any] = {}
        self._rng = rng

    def section_logits(self, obs: Mapping[str, Any]) -> np.ndarray:
        """(batch, S) log-odds of tamping (batched observation dict of numpy arrays)."""
        t = {k: torch.as_tensor(np.asarray(obs[k]), dtype=torch.float32) for k in FEATURE_SCALES if k in obs}
        t["register"] = torch.as_tensor(np.asarray(obs["register"]), dtype=torch.float32)
        self.policy.set_training_mode(False)  # type: ignore[attr-defined]
        with torch.no_grad():
            return self.policy.section_logits(t).cpu().numpy()

    def predict(self, observation: Mapping[str, Any], state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        b, batched = _as_batch(dict(observation))
        logits = self.section_logits(b)
        if deterministic:
            act = logits > 0.0
        else:
            if self._rng is None:
                self._rng = np.random.default_rng()
            act = self._rng.random(logits.shape) < 1.0 / (1.0 + np.exp(-logits))
        act = act.astype(np.int8)
        return (act if batched else act[0]), state

    def reset(self) -> None:
        """Nothing to forget: the policy is stateless."""
