"""What goes wrong, for every floor: the error raised for a scene, a parameter or a path the user gave that cannot
be used (the command line and the nodes turn it into one message and exit code 2), and the command line's other
exit codes, which the reports of a run set too. It stands below every floor so that any of them may use it."""


class SceneError(Exception):
    """A scene that cannot be used; str(error) is the message for the user (one or more lines)."""


EXIT_RUN_FAILED = 1  # a run that failed, or an output that could not be written after the work
EXIT_INACCURATE = 3  # simulate --strict: the run failed a self-check (analysis/self_check.py)
EXIT_INTERRUPTED = 130  # Ctrl-C, as a shell reports a command ended by SIGINT
