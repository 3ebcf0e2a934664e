"""What the backends of renderers built from source share (ART by scripts/build_art.sh, pbrt-v4 by
scripts/build_pbrt.sh): reading the build's env file, choosing the executable to run, and the
message that says how to get one when there is none. Each backend names its own file, key and
script; the rules are the same for all of them, so they live here once."""
import json
import os
import shutil
from pathlib import Path


def built_program(env_file, key):
    """(executable, record) from a build script's env file: None when the file is missing or
    unreadable, has no ``key``, or names an executable that is gone (a build deleted since)."""
    try:
        record = json.loads(Path(env_file).read_text())
        program = Path(record[key])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not (program.is_file() and os.access(program, os.X_OK)):
        return None
    return program, record


def find_program(executable, built, name):
    """The program to run: ``executable`` when given (None if it is not a file), else ``built``
    (the env file's, a Path or None), else ``name`` on PATH."""
    if executable:
        return Path(executable) if Path(executable).is_file() else None
    if built:
        return built
    found = shutil.which(name)
    return Path(found) if found else None


def not_found(program, renderer, executable, env_file, script, option):
    """The availability text of a backend whose program was not found: where it was looked for and
    the ways to give one."""
    where = executable or f"{Path(env_file).parent.name}/{Path(env_file).name} or PATH"
    return (f"{program} ({renderer}) not found in {where}: build it with {script} SRC "
            f"({renderer}'s source), or give it with -e {option}=PATH, the settings file's exec, or PATH")
