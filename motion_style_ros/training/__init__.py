"""Training loops, ONNX export and model cards (torch), by concept:

- :mod:`.data`: Bandai takes (or a user's labelled BVH folder) as feature clips, their
  augmentation, windows and normalisation;
- :mod:`.unlabelled`: clips without style labels (other capture setups) conditioned as a stream is,
  for the generator to restyle in training;
- :mod:`.pseudo_pairs`: those clips stylized by the shipped backends, the best output judge panel 1
  recognises kept as a regression target (distillation);
- :mod:`.losses`: differentiable kinematics and the reconstruction losses of the stylizers;
- :mod:`.loop`: the resumable training loop (checkpoints, budget, log) every stylizer trainer runs,
  on any device and data-parallel under ``torchrun``;
- :mod:`.hardware`: the device (``--device``), the process group, mixed precision;
- :mod:`.export`: ONNX export under the model contract's names, shared card fields, model writing;
- :mod:`.command`: what every ``motion-style train <backend>`` subcommand shares (no torch);
- one package per stylizer with only its own parts, a ``trainer`` (config, networks, step,
  validation, ``train``), an ``export`` (graphs, parity, card, a random stand-in for tests) and a
  ``command`` (its ``train`` subcommand's flags and run, no torch; the package loads the others on
  first use, :mod:`.lazy`): :mod:`.recurrent` (Style-ERD), :mod:`.stgcn`, :mod:`.most`, :mod:`.saae`;
- :mod:`.judges`: the evaluation judges' training, export and cards.
"""
