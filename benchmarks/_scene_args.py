"""The command line the scripts beside this one share: ``SCENE [LEVEL] [FLAGS ...]``."""


def scene_args(argv: list[str], repeat: int | None = None) -> tuple[str, str, list[str], int | None]:
    """``(scene, level, flags, repeat)`` from ``argv``: the scene, the level (default
    "1"; a level is the second word unless that starts with "-"), the rest as flags;
    where ``repeat`` (its default) is given, ``--repeat N`` is taken out of the flags."""
    argv = list(argv)
    if repeat is not None and "--repeat" in argv:
        i = argv.index("--repeat")
        repeat = int(argv[i + 1])
        del argv[i:i + 2]
    scene, rest = argv[0], argv[1:]
    level = rest.pop(0) if rest and not rest[0].startswith("-") else "1"
    return scene, level, rest, repeat
