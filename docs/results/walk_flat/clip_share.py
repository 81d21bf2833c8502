"""How often PPO's clip acts in an A2CF run once the help is over, with the 6 assist actions in
the ratio (``--ppo-assist-in-ratio always``) and without them (``while_helping``).

Each run is branched at checkpoint K (``branch.py``, no overrides, into a temporary folder) and
trained on for N iterations with the PPO update watched: per mini-batch, the share of samples
whose ratio leaves [1 - clip, 1 + clip], and the share whose gradient the clip zeroes (the clipped
term is the max of the two); for the joint ratio the run trains with, and for the motion actions'
own ratio (the 29 joint targets). The run's records are not touched.

    python docs/results/walk_flat/clip_share.py OUT.json K N RUN_DIR...
"""

from __future__ import annotations

import json
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

import torch
from torch.distributions import Normal

sys.path.insert(0, str(Path(__file__).parent))
from branch import branch  # noqa: E402

from optimal_control.files import atomic_write_json  # noqa: E402


def watch(run: Path, k: int, n: int) -> dict:
    from rsl_rl.storage import RolloutStorage

    from a2cf_mb.cli import main
    from rl.agents.models import A2CFActor

    rows: list[dict] = []
    batches: list = []
    generator = RolloutStorage.mini_batch_generator
    log_prob = A2CFActor.get_output_log_prob

    def watched_generator(self, *args, **kwargs):
        for batch in generator(self, *args, **kwargs):
            batches[:] = [batch]
            yield batch

    def watched_log_prob(self, outputs):
        out = log_prob(self, outputs)
        if not batches or batches[0].actions is not outputs:
            return out
        batch = batches[0]
        actors[:] = [self]
        m = self.num_motion_actions
        with torch.no_grad():
            new_mean, new_std = self.distribution.params
            old_mean, old_std = batch.old_distribution_params
            adv = batch.advantages.squeeze(-1)
            log_r = {
                "joint": out - batch.old_actions_log_prob.squeeze(-1),
                "motion": (
                    Normal(new_mean[..., :m], new_std[..., :m]).log_prob(outputs[..., :m]).sum(-1)
                    - Normal(old_mean[..., :m], old_std[..., :m]).log_prob(outputs[..., :m]).sum(-1)
                ),
            }
            row = {}
            clip = clips[0]
            for name, lr in log_r.items():
                r = lr.exp()
                outside = (r - 1).abs() > clip
                zeroed = ((adv > 0) & (r > 1 + clip)) | ((adv < 0) & (r < 1 - clip))
                row[f"{name}_outside"] = outside.float().mean().item()
                row[f"{name}_zeroed"] = zeroed.float().mean().item()
                row[f"{name}_log_ratio_std"] = lr.std().item()
            rows.append(row)
        return out

    clip_grad_norm = torch.nn.utils.clip_grad_norm_
    actors: list = []  # the run's actor, found by its first forward pass

    def watched_clip_grad_norm(parameters, max_norm, *args, **kwargs):
        parameters = list(parameters)
        actor = actors[0] if actors else None
        if actor is not None and any(
            p is q for p in parameters for q in actor.mlp.motion.parameters()
        ):
            m = actor.num_motion_actions
            assist = {id(p) for p in actor.mlp.assist.parameters()} if actor.has_assist else set()
            std = getattr(actor.distribution, "std_param", None)
            if std is None:
                std = actor.distribution.log_std_param
            total = motion = 0.0
            for p in parameters:
                if p.grad is None:
                    continue
                sq = p.grad.detach().pow(2).sum().item()
                total += sq
                if p is std:
                    motion += p.grad.detach()[:m].pow(2).sum().item()
                elif id(p) not in assist:
                    motion += sq
            grads.append({"actor_grad_norm": total**0.5, "motion_grad_norm": motion**0.5,
                          "step_scale": min(1.0, max_norm / (total**0.5 + 1e-6)),
                          "step_scale_motion_alone": min(1.0, max_norm / (motion**0.5 + 1e-6))})  # fmt: skip
        return clip_grad_norm(parameters, max_norm, *args, **kwargs)

    grads: list[dict] = []
    clips: list[float] = []  # the run's clip, read from its config below
    with tempfile.TemporaryDirectory(dir=run.parent) as tmp:
        name = f"{Path(tmp).name}_{run.name}"
        new = branch(run, k, name, {})
        clips[:] = [json.loads((new / "config.json").read_text())["train"]["ppo"]["clip_param"]]
        RolloutStorage.mini_batch_generator = watched_generator
        A2CFActor.get_output_log_prob = watched_log_prob
        torch.nn.utils.clip_grad_norm_ = watched_clip_grad_norm
        try:
            code = main(["train", "--resume", str(new), "--iterations", str(k + n)])
        finally:
            RolloutStorage.mini_batch_generator = generator
            A2CFActor.get_output_log_prob = log_prob
            torch.nn.utils.clip_grad_norm_ = clip_grad_norm
            shutil.rmtree(new, ignore_errors=True)
        if code:
            raise SystemExit(f"training the branch of {run} failed (exit code {code})")
    keys = rows[0].keys() if rows else []
    summary = {"run": run.name, "k": k, "iterations": n, "mini_batches": len(rows),
               **{key: statistics.mean(r[key] for r in rows) for key in keys}}  # fmt: skip
    for key in grads[0] if grads else []:
        summary[key] = statistics.median(g[key] for g in grads)
    summary["steps_grad_clipped"] = (
        statistics.mean(g["step_scale"] < 1.0 for g in grads) if grads else None
    )
    return summary


if __name__ == "__main__":
    if len(sys.argv) < 5:
        raise SystemExit(__doc__)
    out = Path(sys.argv[1])
    try:
        k, n = int(sys.argv[2]), int(sys.argv[3])
    except ValueError:
        raise SystemExit(
            f"K and N must be whole numbers of iterations, got {sys.argv[2:4]}"
        ) from None
    if not out.parent.is_dir():
        raise SystemExit(f"{out.parent} does not exist; give OUT.json in an existing folder")
    results = [watch(Path(r), k, n) for r in sys.argv[4:]]
    atomic_write_json(out, results, indent=1)
    for r in results:
        print(json.dumps(r))
