"""Motion data: loaders (BVH, ASF/AMC, AMASS), retargeting, virtual trackers, the CMU split."""


class MotionFileError(ValueError):
    """A motion file that cannot be read; the message names the file and the problem."""

    def __init__(self, path, problem: str):
        super().__init__(f"{path}: {problem}")
        self.path = str(path)
        self.problem = problem
