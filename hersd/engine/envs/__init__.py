"""The environments a run trains on: what makes an env goal-conditioned and its reward rule (``goal_envs``), and
making an env and reading what a run needs of it (``make``); the tasks by name are the contract's
(:mod:`hersd.contract.tasks`). Importing the package loads neither gymnasium nor MuJoCo."""
