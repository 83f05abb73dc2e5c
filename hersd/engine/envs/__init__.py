"""The environments a run trains on: the tasks by name (``tasks``), what makes an env goal-conditioned and its
reward rule (``goal_envs``), and making an env and reading what a run needs of it (``make``). Light: importing the
package or ``tasks`` loads neither gymnasium nor MuJoCo."""
