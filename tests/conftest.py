"""Shared test set-up: a persistent JAX compilation cache and compiled-per-variant fixtures."""

import os
import pathlib

import jax

_CACHE = pathlib.Path(__file__).resolve().parents[1] / ".cache" / "jax"
jax.config.update("jax_compilation_cache_dir", os.environ.get("DPC_JAX_CACHE", str(_CACHE)))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
