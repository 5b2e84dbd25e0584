"""Running a render: the plan, the executors (local processes, Ray) and the workers that write samples."""
