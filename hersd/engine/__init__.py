"""One training run (torch and MuJoCo): the loop, its state and checkpoint, the envs, the replay buffer, the
learners, the bias evaluation, the policy animations and the ``hersd-train`` and ``hersd-render`` commands.
Imports the contract (:mod:`hersd.contract`), never a layer above it. Importing the package loads nothing."""
