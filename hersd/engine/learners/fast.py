"""``update=fast``: DDPG's and TD3's update with the networks' forward and backward passes written by hand.

The autograd update's rule (``DDPG.update``: the same losses, target, optimiser and checkpoint) in fewer
float32 passes and without an autograd graph (docs/LEARNERS.md, "The fast update"):

- each MLP's hidden layers run as oneDNN matmuls with the bias and ReLU fused in (:func:`_linear`: torch's
  float32 ``mm`` is MKL's, which on AMD CPUs runs at half oneDNN's rate), the output layer's narrow products
  as ``torch.addmm``/``mm`` into kept buffers; the backward writes each parameter's ``.grad`` (never None), the
  ReLU mask read from the kept activations, which the gradient then overwrites;
- the first critic's passes over the critic loss's rows and the actor loss's in one product of 2B rows;
- the critic's loss and the actor's share one buffer of inputs, (s, a / max_action) above (s, pi(s)); the
  actor loss's -mean Q_1(s, pi) goes back through the critic's weights (not into their gradients: the autograd
  update detaches them there) to the action columns only, dL/dpi, then through tanh and the actor by hand;
- the target r + gamma * min_i Q_i'(s', pi'(s')) and its clip without autograd, the goal normalised once
  for s and s';
- the narrow products, the first layer's weight gradient and dL/dpi, computed as their transposes (MKL runs
  a (rows x 4) product several times slower than its (4 x rows) transpose);
- the learner's own fused Adam (its groups, settings and state, so a checkpoint of either update loads into
  the other), its kernel called directly (``torch._fused_adam_``, as ``Adam.step`` calls it: the same numbers,
  without the step's bookkeeping).

With ``precision=bf16`` the same passes run their hidden layers' products in bfloat16 (:class:`HandMLPBF16`: bf16
copies of the float32 master weights, refreshed after each optimiser step, target move and checkpoint load; the
output layers, losses, target and Adam in float32; docs/LEARNERS.md, "Precision"): gradients within 0.15 of each
gradient's largest element of the float32 autograd update's, as close as bf16 autocast's.

Its sums run in another order than autograd's (oneDNN's products, of other shapes, the bias added inside the
product, the target's r + gamma Q' in one pass), so its numbers differ from the default update's in the last
bits and a run's grow apart from there: ``update=fast`` is a run of its own (its folder differs), and the default
update stays the code every earlier run ran. ``tests/test_fast_update.py`` holds its gradients to
autograd's. SAC has none: the config refuses ``learner=sac update=fast``.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import torch
from torch import nn

from hersd.contract.config import no_fast_update
from hersd.contract.errors import ConfigError
from hersd.engine.learners.base import GoalConditionedLearner, RunningNormalizer, UpdateStats
from hersd.engine.learners.ddpg import DDPG
from hersd.engine.learners.td3 import TD3
from hersd.engine.replay.buffer import TransitionBatch

_threshold_backward = torch.ops.aten.threshold_backward.grad_input  # g * (h > 0), into an out tensor
ONEDNN = torch.backends.mkldnn.is_available()  # :func:`_linear`'s products by oneDNN


def _linear(x: torch.Tensor, weight: torch.Tensor, bias: Optional[torch.Tensor] = None,
            relu: bool = False) -> torch.Tensor:
    """x (rows, in) @ weight (out, in).T (+ bias, then ReLU) -> (rows, out), a new float32 tensor: by oneDNN's
    matmul on a CPU (torch's own float32 ``mm`` goes to MKL, which on AMD CPUs runs its AVX2 code, half oneDNN's
    rate on family 26: docs/LEARNERS.md, "The fast update"); by ``torch.nn.functional.linear`` on other devices
    and where this torch has no oneDNN."""
    if ONEDNN and x.device.type == "cpu":
        return torch.ops.mkldnn._linear_pointwise(x, weight, bias, "relu" if relu else "none", [], "")
    product = torch.nn.functional.linear(x, weight, bias)
    return product.relu_() if relu else product


def _output_backward(grad: torch.Tensor, weight: torch.Tensor, out: Optional[torch.Tensor] = None) -> torch.Tensor:
    """dL/d input of an output layer: grad (rows, out) @ weight (out, in) -> (rows, in); with one output (the
    critics) the same products as a broadcast multiply, which runs faster than a product of inner size 1."""
    if weight.shape[0] == 1:
        return torch.mul(grad, weight, out=out)
    return torch.mm(grad, weight, out=out)


class Activations:
    """Buffers of one network's passes, shared by a network and its target (the target's passes end before the
    network's begin), for up to ``rows`` rows: the output (float32) and one scratch gradient (in ``hidden_dtype``:
    the gradient at the output layer's input); with bf16 hidden layers (:class:`HandMLPBF16`) also each hidden
    layer's output (bf16) and ``widened``, the last hidden layer's output in float32 (the float32 output layer's
    input, then its gradient)."""

    def __init__(self, hidden_dtype: torch.dtype = torch.float32) -> None:
        self.hidden_dtype = hidden_dtype
        self.rows = 0
        self.hidden: list[torch.Tensor] = []
        self.output: Optional[torch.Tensor] = None
        self.scratch: Optional[torch.Tensor] = None
        self.widened: Optional[torch.Tensor] = None

    def take(self, weights: list[torch.Tensor], rows: int) -> tuple[list[torch.Tensor], torch.Tensor, torch.Tensor]:
        """Views of ``rows`` rows of the buffers (made anew when more rows are asked for than they hold)."""
        if rows > self.rows:
            like, dtype = weights[0], self.hidden_dtype
            self.output = like.new_empty(rows, weights[-1].shape[0])
            self.scratch = like.new_empty(rows, max(weight.shape[0] for weight in weights[:-1]), dtype=dtype)
            if dtype != torch.float32:
                self.hidden = [like.new_empty(rows, weight.shape[0], dtype=dtype) for weight in weights[:-1]]
                self.widened = like.new_empty(rows, weights[-1].shape[1])
            self.rows = rows
        return [h[:rows] for h in self.hidden], self.output[:rows], self.scratch[:rows]


class HandMLP:
    """Forward and backward of a ReLU :func:`hersd.engine.learners.base.mlp` by hand, on its own parameters (which
    Adam and ``load_state_dict`` change in place). The hidden layers' products run in oneDNN (:func:`_linear`,
    the ReLU and bias fused in; new tensors, the activations kept for the backward, which overwrites them with
    the gradient); the output layer's narrow ones in ``torch.addmm``/``mm`` into the kept output buffer and
    ``.grad``."""

    def __init__(self, net: nn.Sequential, grads: bool, buffers: Optional[Activations] = None):
        layers = [module for module in net if isinstance(module, nn.Linear)]
        self.weights = [layer.weight for layer in layers]
        self.biases = [layer.bias for layer in layers]
        if grads:  # never None: each backward writes them (into them or anew), the optimiser reads them
            for parameter in (*self.weights, *self.biases):
                parameter.grad = torch.zeros_like(parameter)
        self.buffers = buffers if buffers is not None else Activations()
        self.inputs: Optional[torch.Tensor] = None
        self.hidden: list[torch.Tensor] = []

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        """(rows, in) -> (rows, out), keeping the inputs and the ReLU outputs for :meth:`backward`; the
        output is a buffer that the next forward overwrites."""
        output = self.buffers.take(self.weights, inputs.shape[0])[1]
        h, self.inputs, self.hidden = inputs, inputs, []
        for weight, bias in zip(self.weights[:-1], self.biases[:-1]):
            h = _linear(h, weight, bias, relu=True)
            self.hidden.append(h)
        return torch.addmm(self.biases[-1], h, self.weights[-1].t(), out=output)

    def backward(self, grad_output: torch.Tensor, weight_rows: int,
                 input_rows: Optional[slice] = None, input_cols: Optional[slice] = None) -> Optional[torch.Tensor]:
        """Back from dL/d output (rows, out) of the last forward: each parameter's ``.grad`` set to the
        gradient of the first ``weight_rows`` rows; returns dL/d inputs[input_rows, input_cols] (or None).
        Each hidden layer's kept output is overwritten by the gradient at its input (it is not needed after)."""
        g, last = grad_output, len(self.weights) - 1
        scratch = self.buffers.take(self.weights, g.shape[0])[2]
        for i in reversed(range(len(self.weights))):
            below = self.hidden[i - 1] if i else self.inputs
            if weight_rows:
                self._parameter_grads(i, g[:weight_rows], below[:weight_rows])
            if i:
                dh = (_output_backward(g, self.weights[i], out=scratch[:, :below.shape[1]]) if i == last
                      else _linear(g, self.weights[i].t()))
                g = _threshold_backward(dh, below, 0, grad_input=below)
        if input_rows is None:
            return None
        # (rows, few columns) as the transpose of (few, rows): a product of that shape runs several times faster
        return torch.mm(self.weights[0][:, input_cols].t(), g[input_rows].t()).t()

    def _parameter_grads(self, i: int, g: torch.Tensor, below: torch.Tensor) -> None:
        """Layer i's weight and bias gradients into their ``.grad``, from the gradient at its output g (rows, out)
        and its input ``below`` (rows, in)."""
        if i == len(self.weights) - 1:  # the output layer's few rows
            torch.mm(g.t(), below, out=self.weights[i].grad)
        elif i:  # a new tensor made the .grad (the optimiser reads .grad anew at each step)
            self.weights[i].grad = _linear(g.t(), below.t())
        else:  # the first layer's few input columns: the product as (in, out) runs faster, then transposed
            self.weights[0].grad.copy_(torch.mm(below.t(), g).t())
        torch.sum(g, 0, out=self.biases[i].grad)

    def refresh(self) -> None:
        """Make the weights the passes use those of the parameters (after they moved): they are the same here."""


class HandMLPBF16(HandMLP):
    """:class:`HandMLP` with the hidden layers in bfloat16 (``update=fast precision=bf16``): their products on
    bf16 copies of the float32 master weights and biases (:meth:`refresh`: once per optimiser step), on bf16
    inputs and activations, float32 accumulation inside each product (oneDNN's, as under autocast), their weight
    gradients rounded to bf16 and written into the float32 ``.grad``, bias gradients summed in float32. The
    output layer (critics' 256 -> 1, actors' 256 -> A) runs in float32 on the last hidden layer widened to
    float32, as ``FullPrecisionLinear`` does under autocast. ReLU and its backward mask run on the bf16 bits read
    as int16 (a bf16 is negative exactly when its int16 is: the same numbers as ``relu_``, in a quarter of the
    time of this torch's bf16 kernels; a NaN with its sign bit set becomes 0, and the float32 losses still
    report a diverged run); bias gradients are summed in float32 from the gradient widened into a kept buffer."""

    def __init__(self, net: nn.Sequential, grads: bool, buffers: Optional[Activations] = None):
        super().__init__(net, grads, buffers if buffers is not None else Activations(torch.bfloat16))
        self.low_weights = [weight.detach().to(torch.bfloat16) for weight in self.weights[:-1]]
        self.low_biases = [bias.detach().to(torch.bfloat16) for bias in self.biases[:-1]]
        self.low_grads = [torch.empty_like(weight) for weight in self.low_weights[1:]] if grads else []

    def refresh(self) -> None:
        """The bf16 copies rounded anew from the float32 master weights and biases."""
        torch._foreach_copy_([*self.low_weights, *self.low_biases], [*self.weights[:-1], *self.biases[:-1]])

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        """(rows, in) float32 -> (rows, out) float32, the inputs rounded to bf16 once; keeps the bf16 inputs and
        ReLU outputs and the last one widened for :meth:`backward`; the output is a buffer the next forward
        overwrites."""
        hidden, output, _ = self.buffers.take(self.weights, inputs.shape[0])
        h = self.inputs = inputs.to(torch.bfloat16)
        for weight, bias, out in zip(self.low_weights, self.low_biases, hidden):
            h = torch.addmm(bias, h, weight.t(), out=out)
            h.view(torch.int16).clamp_min_(0)
        self.hidden = hidden
        widened = self.buffers.widened[:inputs.shape[0]].copy_(h)
        return torch.addmm(self.biases[-1], widened, self.weights[-1].t(), out=output)

    def backward(self, grad_output: torch.Tensor, weight_rows: int,
                 input_rows: Optional[slice] = None, input_cols: Optional[slice] = None) -> Optional[torch.Tensor]:
        """:meth:`HandMLP.backward` from dL/d output (rows, out) float32: the output layer's in float32, the
        gradient at its input rounded to bf16, the hidden layers' in bf16; dL/d inputs returned in float32."""
        rows, last = grad_output.shape[0], len(self.weights) - 1
        scratch, widened = self.buffers.take(self.weights, rows)[2], self.buffers.widened[:rows]
        if weight_rows:
            torch.mm(grad_output[:weight_rows].t(), widened[:weight_rows], out=self.weights[last].grad)
            torch.sum(grad_output[:weight_rows], 0, out=self.biases[last].grad)
        below = self.hidden[-1]
        dh = scratch[:, :below.shape[1]].copy_(_output_backward(grad_output, self.weights[last], out=widened))
        g = _bf16_threshold_backward(dh, below)
        for i in reversed(range(last)):
            below = self.hidden[i - 1] if i else self.inputs
            if weight_rows:
                self._low_parameter_grads(i, g[:weight_rows], below[:weight_rows])
            if i:
                dh = torch.mm(g, self.low_weights[i], out=scratch[:, :below.shape[1]])
                g = _bf16_threshold_backward(dh, below)
        if input_rows is None:
            return None
        return torch.mm(self.low_weights[0][:, input_cols].t(), g[input_rows].t()).t().float()

    def _low_parameter_grads(self, i: int, g: torch.Tensor, below: torch.Tensor) -> None:
        """Hidden layer i's weight gradient (a bf16 product) and bias gradient (a float32 sum) into their float32
        ``.grad``, from the bf16 gradient at its output g (rows, out) and its bf16 input ``below`` (rows, in)."""
        if i:
            self.weights[i].grad.copy_(torch.mm(g.t(), below, out=self.low_grads[i - 1]))
        else:  # the first layer's few input columns: the product as (in, out), then transposed
            self.weights[0].grad.copy_(torch.mm(below.t(), g).t())
        wide = self.buffers.widened[:g.shape[0], :g.shape[1]].copy_(g)
        torch.sum(wide, 0, out=self.biases[i].grad)


def _bf16_threshold_backward(grad: torch.Tensor, below: torch.Tensor) -> torch.Tensor:
    """grad * (below > 0) into ``below`` (both bf16, (rows, width)), on their bits as int16 (a positive bf16 is
    a positive int16)."""
    _threshold_backward(grad.view(torch.int16), below.view(torch.int16), 0, grad_input=below.view(torch.int16))
    return below


class FastUpdate:
    """The hand-written update of a DDPG-like learner (DDPG, TD3), mixed in before the learner's class."""

    def _hand_networks(self) -> None:
        """Hand passes over every network (gradients for the online ones), and no input buffers yet."""
        online, hand = ("actor", *self.CRITICS), HandMLPBF16 if self.precision == "bf16" else HandMLP
        self.hand = {name: hand(getattr(self, name), grads=True) for name in online}
        self.hand.update({f"{name}_target": hand(getattr(self, f"{name}_target"), grads=False,
                                                 buffers=self.hand[name].buffers) for name in online})
        self._input_buffers: dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = {}
        # Adam's kernel is called directly only for the settings the learners give it (else Adam.step)
        self._direct_adam = all(group["fused"] and not (group["amsgrad"] or group["maximize"] or group["capturable"]
                                                        or group["differentiable"] or group["decoupled_weight_decay"])
                                for group in self.optimizer.param_groups)

    def _batch_inputs(self, batch: TransitionBatch) -> tuple[torch.Tensor, torch.Tensor]:
        """The critics' rows (2B, in + A): (s, a / max_action) above (s, ...) whose action columns the actor
        fills; and the target's (B, in + A), (s', ...). Raw obs and goals are clipped and normalised as
        ``_inputs`` does, the goal once for both."""
        rows, obs_dim, in_dim = batch.obs.shape[0], self.obs_norm.total.shape[0], self.actor[0].in_features
        if rows not in self._input_buffers:
            like, width = self.hand["actor"].weights[0], in_dim + batch.action.shape[1]
            self._input_buffers[rows] = (like.new_empty(2 * rows, width), like.new_empty(rows, width),
                                         like.new_empty(2 * rows, 1))
        critic_rows, next_rows, _ = self._input_buffers[rows]
        self._normalised(self.obs_norm, batch.obs, critic_rows[:rows, :obs_dim])
        self._normalised(self.obs_norm, batch.next_obs, next_rows[:, :obs_dim])
        self._normalised(self.goal_norm, batch.goal, critic_rows[:rows, obs_dim:in_dim])
        next_rows[:, obs_dim:in_dim] = critic_rows[:rows, obs_dim:in_dim]
        critic_rows[rows:, :in_dim] = critic_rows[:rows, :in_dim]
        torch.div(self.tensor(batch.action), self.max_action, out=critic_rows[:rows, in_dim:])
        return critic_rows, next_rows

    def _normalised(self, norm: RunningNormalizer, raw: np.ndarray, out: torch.Tensor) -> None:
        """clip(raw, +-clip_obs) normalised by ``norm`` and clipped to +-clip_norm, into ``out``."""
        torch.clamp(self.tensor(raw), -self.cfg.clip_obs, self.cfg.clip_obs, out=out)
        out.sub_(norm.mean).div_(norm.std).clamp_(-self.cfg.clip_norm, self.cfg.clip_norm)

    def _target(self, next_rows: torch.Tensor, reward: np.ndarray) -> torch.Tensor:
        """r + gamma * min_i Q_i'(s', a') clipped to ``target_range`` (B, 1); a' into ``next_rows``' action columns."""
        in_dim = self.actor[0].in_features
        torch.tanh(self.hand["actor_target"].forward(next_rows[:, :in_dim]), out=next_rows[:, in_dim:])
        self.smooth_target_action(next_rows[:, in_dim:])
        next_q = self.hand[f"{self.CRITICS[0]}_target"].forward(next_rows)
        for critic in self.CRITICS[1:]:
            next_q = torch.minimum(next_q, self.hand[f"{critic}_target"].forward(next_rows))
        target = torch.add(self.tensor(reward).unsqueeze(1), next_q, alpha=self.gamma)
        return target.clamp_(*self.target_range)

    def smooth_target_action(self, next_action: torch.Tensor) -> None:
        """Change a' = pi'(s') (B, A, tanh scale) in place before the target critics see it: DDPG leaves it."""

    @torch.no_grad()
    def update(self, batch: TransitionBatch) -> UpdateStats:
        """One step of the critics and, if due, the actor: ``DDPG.update``'s rule."""
        rows, in_dim = batch.obs.shape[0], self.actor[0].in_features
        critic_rows, next_rows = self._batch_inputs(batch)
        target = self._target(next_rows, batch.reward)
        actor_due = self.actor_step_due()
        if actor_due:  # pi(s) = tanh(actor(s)) into the lower rows' action columns
            torch.tanh(self.hand["actor"].forward(critic_rows[:rows, :in_dim]), out=critic_rows[rows:, in_dim:])
        critic_loss, q, policy_q = self._critics_backward(critic_rows, target, actor_due)
        if actor_due:
            self.last_actor_loss = self._actor_backward(critic_rows[rows:, in_dim:], *policy_q)
        self._step(actor_due)
        self._refresh(("actor", *self.CRITICS) if actor_due else self.CRITICS)
        return UpdateStats.of(critic_loss, self.last_actor_loss, q, batch)

    def _refresh(self, names: tuple[str, ...]) -> None:
        """The weights the hand passes of networks ``names`` use made those of their parameters (bf16: rounded)."""
        for name in names:
            self.hand[name].refresh()

    def update_targets(self) -> None:
        """The learner's polyak move of the targets, then their hand passes' weights refreshed."""
        super().update_targets()
        self._refresh(tuple(f"{name}_target" for name in self.TARGETS))

    def load_state_dict(self, state: dict) -> None:
        """The learner's checkpoint loaded into the parameters, then every hand pass's weights refreshed."""
        super().load_state_dict(state)
        self._refresh(tuple(self.hand))

    def _critics_backward(self, critic_rows: torch.Tensor, target: torch.Tensor, actor_due: bool
                          ) -> tuple[float, torch.Tensor, tuple[float, Optional[torch.Tensor]]]:
        """Each critic's gradient of its term of sum_i mean (Q_i(s, a) - target)^2 into its ``.grad``, from the
        upper B rows of ``critic_rows``. With the actor due, the first critic's passes take all 2B rows at once
        (one product of 2B rows runs faster than two of B), the lower ones (s, pi(s)) giving -mean Q_1(s, pi) and
        its gradient w.r.t. pi (B, A), the critic's gradients from the upper rows only.
        Returns (the critic loss, Q_1(s, a) (B, 1), (-mean Q_1(s, pi), that gradient)) (0.0, None if not due)."""
        rows = target.shape[0]
        grad = self._input_buffers[rows][2]
        losses, q, policy_q = [], None, (0.0, None)
        for index, critic in enumerate(self.CRITICS):
            hand, both = self.hand[critic], index == 0 and actor_due
            value = hand.forward(critic_rows if both else critic_rows[:rows])
            q = value[:rows].clone() if index == 0 else q
            diff = torch.sub(value[:rows], target)
            losses.append(torch.dot(diff.view(-1), diff.view(-1)))
            torch.mul(diff, 2.0 / rows, out=grad[:rows])
            if not both:
                hand.backward(grad[:rows], rows)
                continue
            policy_loss = -value[rows:].mean().item()
            grad[rows:].fill_(-1.0 / rows)
            dpi = hand.backward(grad, rows, slice(rows, None), slice(self.actor[0].in_features, None))
            policy_q = (policy_loss, dpi)
        return torch.stack(losses).sum().item() / rows, q, policy_q

    def _actor_backward(self, pi: torch.Tensor, policy_loss: float, dpi: torch.Tensor) -> float:
        """The actor's gradient of -mean Q_1(s, pi) + action_l2 * mean(pi^2) into its ``.grad``, given pi (B, A),
        the first term and its gradient w.r.t. pi; returns the actor loss."""
        l2, size = self.cfg.action_l2, pi.numel()
        flat = pi.reshape(-1)
        loss = policy_loss + l2 * torch.dot(flat, flat).item() / size
        dpi.add_(pi, alpha=2.0 * l2 / size)
        self.hand["actor"].backward(torch.ops.aten.tanh_backward(dpi, pi), pi.shape[0])
        return loss

    def _step(self, actor_due: bool) -> None:
        """The learner's Adam on the gradients just written, the actor's left out when it was not due: its
        fused kernel called as ``torch.optim.Adam(fused=True).step`` calls it, without the step's bookkeeping."""
        optimizer = self.optimizer
        groups = optimizer.param_groups if actor_due else optimizer.param_groups[1:]
        if not self._direct_adam or any(p not in optimizer.state for group in groups for p in group["params"]):
            self._step_by_optimizer(actor_due)  # the first step makes Adam's state
            return
        for group in groups:
            params = group["params"]
            states = [optimizer.state[p] for p in params]
            steps = [state["step"] for state in states]
            torch._foreach_add_(steps, 1)
            beta1, beta2 = group["betas"]
            torch._fused_adam_(params, [p.grad for p in params], [s["exp_avg"] for s in states],
                               [s["exp_avg_sq"] for s in states], [], steps, amsgrad=False, lr=group["lr"],
                               beta1=beta1, beta2=beta2, weight_decay=group["weight_decay"], eps=group["eps"],
                               maximize=False, grad_scale=None, found_inf=None)

    def _step_by_optimizer(self, actor_due: bool) -> None:
        """``optimizer.step()`` on the gradients just written, the actor's left out when it was not due."""
        if actor_due:
            self.optimizer.step()
            return
        actor = list(self.actor.parameters())
        kept = [p.grad for p in actor]
        for p in actor:
            p.grad = None
        self.optimizer.step()
        for p, grad in zip(actor, kept):
            p.grad = grad


class FastDDPG(FastUpdate, DDPG):
    """``learner=ddpg update=fast``: DDPG with the hand-written update (no ``NAME``: the run's learner is ddpg)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._hand_networks()


class FastTD3(FastUpdate, TD3):
    """``learner=td3 update=fast``: TD3 with the hand-written update and TD3's smoothed target action."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._hand_networks()

    def smooth_target_action(self, next_action: torch.Tensor) -> None:
        """TD3's a' = clip(pi'(s') + clip(N(0, policy_noise), +-noise_clip), +-1), the noise drawn as TD3 draws it."""
        noise = (torch.randn_like(next_action) * self.td3.policy_noise).clamp(-self.td3.noise_clip, self.td3.noise_clip)
        next_action.add_(noise).clamp_(-1.0, 1.0)


FAST_CLASSES: dict[type, type] = {DDPG: FastDDPG, TD3: FastTD3}


def fast_learner_class(cls: type[GoalConditionedLearner]) -> type[GoalConditionedLearner]:
    """The class of ``update=fast`` for learner class ``cls``; ConfigError (one line) if it has none."""
    if cls not in FAST_CLASSES:
        raise ConfigError(no_fast_update(getattr(cls, "NAME", cls.__name__)))
    return FAST_CLASSES[cls]
