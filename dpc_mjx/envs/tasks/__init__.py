"""The tasks, one module each; a task owns its scene, its arms and its script.

- `reaching`: the training task (robot on a floor; random arm targets, pushes, payloads);
- `pushing`: a free box pushed with the arm while walking;
- `carrying`: a ball per arm carried from one table to another (`carrying_high`: 0.45 m tables);
- `lifting`: a ball per arm welded in the gripper, lifted while walking;
- `scripts`: shared by the object tasks: scripted arm waypoints, the IK that finds them, and the
  arm check (`check_task_arms`).

Each task's env class (a `DpcEnv`) declares `TASK` (its name), `DEFAULT_ARM` (a variant of
`dpc_mjx.robots.VARIANTS`), `check_arm` (the arms it accepts) and `scene_spec(arm)` (its robot
and objects as an `mujoco.MjSpec`, built from `dpc_mjx.robots.objects`); the module holds the
object sizes, masses and places, and `default_config()`. A new task is a module here and a line
in `dpc_mjx.envs.registry`.
"""
