"""Running a scene: preflight (sizes, memory), the output directory and its lock, launching
participants, the coupler's messaging client, the runner over the plan, studies."""
