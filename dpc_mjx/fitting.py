"""Minibatch Adam with early stopping, shared by the adapter (`adapter.train`) and the actor's
regression on the oracle (`policy.regression`).

One epoch is one jitted `lax.scan` over shuffled minibatches of the training arrays (the last
partial batch is dropped); after each epoch the loss on the validation arrays is computed, the
parameters of the best validation epoch are kept, and training stops after `patience` epochs
without improvement (at most `epochs`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jp
import numpy as np
import optax

from dpc_mjx.errors import DpcError
from dpc_mjx.progress import bar

Loss = Callable[[Any, tuple], jax.Array]  # (params, batch: tuple of (rows, ...) arrays) -> ()


def fit(
    loss: Loss,
    params: Any,
    train: tuple,
    val: tuple,
    *,
    learning_rate: float,
    batch_size: int,
    epochs: int,
    patience: int,
    key: jax.Array,
    diverged_hint: str,
    progress: bool = False,
    desc: str = "fit",
) -> tuple[Any, dict]:
    """The best-validation params and the history {'train_loss', 'val_loss': per epoch,
    'best_epoch' (0-based index into them), 'epochs', 'seconds'}. `train` and `val` are tuples of
    arrays with one row per sample. A non-finite loss raises `DpcError` ending in
    `diverged_hint` (what to change)."""
    n = len(train[0])
    bs = min(batch_size, n)
    n_batches = n // bs
    opt = optax.adam(learning_rate)

    @jax.jit
    def epoch(params, opt_state, key):
        order = jax.random.permutation(key, n)[: n_batches * bs].reshape(n_batches, bs)

        def step(carry, rows):
            p, s = carry
            batch = jax.tree.map(lambda a: a[rows], train)
            value, grads = jax.value_and_grad(loss)(p, batch)
            updates, s = opt.update(grads, s, p)
            return (optax.apply_updates(p, updates), s), value

        (params, opt_state), values = jax.lax.scan(step, (params, opt_state), order)
        return params, opt_state, jp.mean(values), loss(params, val)

    opt_state = opt.init(params)
    history = {"train_loss": [], "val_loss": []}
    best, best_val, best_epoch = params, np.inf, -1
    t0 = time.perf_counter()
    with bar(epochs, desc, "epoch", progress) as pbar:
        for i in range(epochs):
            key, k = jax.random.split(key)
            params, opt_state, tr_loss, va_loss = epoch(params, opt_state, k)
            tr_loss, va_loss = float(tr_loss), float(va_loss)
            if not (np.isfinite(tr_loss) and np.isfinite(va_loss)):
                raise DpcError(
                    f"{desc}: training diverged at epoch {i} (train loss {tr_loss}, validation "
                    f"{va_loss}); {diverged_hint}"
                )
            history["train_loss"].append(tr_loss)
            history["val_loss"].append(va_loss)
            if va_loss < best_val:
                best, best_val, best_epoch = params, va_loss, i
            pbar.set_postfix(train=f"{tr_loss:.3f}", val=f"{va_loss:.3f}")
            pbar.update(1)
            if i - best_epoch >= patience:
                break
    history.update(best_epoch=best_epoch, epochs=len(history["val_loss"]))
    history["seconds"] = time.perf_counter() - t0
    return best, history
