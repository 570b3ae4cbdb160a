"""The ``sunsim`` commands that the command line (:mod:`simcore.cli`) adds whole: each one's options, its checks
and what it prints; the work itself is done by the stages below."""
