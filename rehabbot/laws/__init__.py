"""The task's laws, written once over an array namespace.

Every rule that decides what an action does, what the patient's body answers, when the
safety rules stop an episode and what an agent is paid is a pure function here, of arrays
and of the array namespace ``xp`` they belong to: NumPy for the CPU env (one world, or many
at once) and ``jax.numpy`` for the batched backend. The backends only step physics and read
MuJoCo's data; they call these functions for everything else, so a law exists once.

Rules of the layer:

* no MuJoCo, no JAX import (``xp`` is passed in: :func:`rehabbot.laws.namespace.namespace_of`
  tells NumPy from JAX arrays without importing JAX), no state: a law takes the state it
  needs and returns the new state;
* no in-place writes (JAX arrays are immutable): ``xp.where`` instead of masked assignment;
* leading batch axes are allowed everywhere: a law written for one world's ``(n,)`` arrays
  runs on ``(worlds, n)`` arrays unchanged.
"""
