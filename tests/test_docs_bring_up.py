"""docs/bring-up.md, the checklist for a real rig, runs as written: nobody can try its hardware steps here, so the
page must not drift from the code unseen.

* Every command line of its ``sh`` blocks starts a program the page may name: a console script of pyproject.toml
  (also by its installed path, ``/opt/ghnerf/venv/bin/ghnerf-daemon``), a project script (``systemd/install.sh``),
  or one of the system tools listed in :data:`SYSTEM_TOOLS`. tests/test_docs_commands.py checks the options of the
  project's commands on every doc, but passes over a program it does not know, so a misspelled ``ghnerf-deamon``
  would go through there; here it fails.
* The project's commands (``sudo -u ghnerf`` before them included) take each subcommand and option as written,
  by test_docs_commands' parser check.
* Every rig and sink URL on the page parses for its backend as the daemon's ``--validate-config`` parses it
  (nothing is opened); ``/etc/ghnerf/rig.json`` stands for a rig file ``ghcal solve`` wrote.
* The first rehearsal (the example config and ``--validate-config``) runs in a scratch folder.
* Each ``sh`` block makes (``mkdir -p``) every relative folder its redirections write into, so a rehearsal runs
  whether or not the one before it was (5a's needs socat).
"""
from __future__ import annotations

import dataclasses
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests import test_docs_commands as doc_commands

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "bring-up.md"

#: the programs other than the project's that the page may run (anything else is a typo or a new tool to add here)
SYSTEM_TOOLS = frozenset({
    "cat", "cp", "echo", "id", "install", "jq", "journalctl", "kill", "ls", "lsusb", "mkdir", "setserial", "sleep",
    "socat", "sudoedit", "systemctl", "udevadm", "v4l2-ctl",
})
#: words that run the rest of the line as the command, and the options of theirs that take a value
WRAPPERS = {"sudo": {"-u", "-g"}, "timeout": set(), "nice": {"-n"}}
REDIRECTIONS = {">", ">>", "<", "2>", "&>"}
SEPARATORS = {"&&", "||", "|", ";", "&"}
RIG_SCHEMES = ("depthai", "opencv", "sim", "replay")
SINK_SCHEMES = ("serial", "usb", "udp", "vmc", "file")
URL = re.compile(rf"\b(?:{'|'.join(RIG_SCHEMES + SINK_SCHEMES)})://[^\s\"'`\]),]*")
#: the rig file the page's URLs name, as installed on the device
DEVICE_RIG_FILE = "/etc/ghnerf/rig.json"


def sh_lines(text: str) -> list[tuple[int, str]]:
    """(line number, logical line) of every ``sh`` block; comments and blank lines left out."""
    found: list[tuple[int, str]] = []
    in_sh = in_other = False
    for number, line in enumerate(text.splitlines(), start=1):
        fence = re.match(r"\s*```\s*(\w*)", line)
        if fence and not (in_sh or in_other):
            in_sh, in_other = fence.group(1) == "sh", fence.group(1) != "sh"
            continue
        if fence:
            in_sh = in_other = False
            continue
        if in_sh and line.strip() and not line.lstrip().startswith("#"):
            found.append((number, line.strip()))
    return found


def blocks(text: str, language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", text, flags=re.S | re.M)


def commands(line: str) -> list[list[str]]:
    """The commands of a shell line, each as its words from the program on: separators split them, a redirection's
    target is dropped, ``VAR=value`` prefixes and wrappers (``sudo -u ghnerf``) are passed over."""
    found: list[list[str]] = []
    current: list[str] = []
    skip_next = False
    for word in shlex.split(line, comments=True):
        if skip_next:
            skip_next = False
        elif word in SEPARATORS:
            found.append(current)
            current = []
        elif word in REDIRECTIONS:
            skip_next = True
        else:
            current.append(word)
    found.append(current)
    return [_program_on(words) for words in found if _program_on(words)]


def _program_on(words: list[str]) -> list[str]:
    i = 0
    while i < len(words):
        if doc_commands.ENV_ASSIGNMENT.match(words[i]):
            i += 1
        elif words[i] in WRAPPERS:
            wrapper = words[i]
            i += 1
            while i < len(words) and words[i].startswith("-"):
                i += 2 if words[i] in WRAPPERS[wrapper] else 1
            if wrapper == "timeout":
                i += 1  # its duration
        else:
            break
    return words[i:]


def is_assignment(line: str) -> bool:
    return all(doc_commands.ENV_ASSIGNMENT.match(w) for w in shlex.split(line, comments=True))


def program_problem(words: list[str], project: doc_commands.Project) -> str | None:
    head = words[0]
    name = head.rsplit("/", 1)[-1]
    if name in project.scripts or (project.is_project_path(head) and (project.root / head).is_file()):
        return None
    if head in SYSTEM_TOOLS:
        return None
    return f"{head}: not a program of the project (pyproject.toml's scripts, a script in the repository) nor a " \
           f"system tool the page allows (SYSTEM_TOOLS)"


def page_problems(text: str, programs: doc_commands.Programs) -> list[str]:
    """Every program and option on the page that the project's programs would not take, with its line."""
    problems = []
    for number, line in sh_lines(text):
        where = f"docs/bring-up.md:{number}"
        if is_assignment(line):
            continue
        for words in commands(line):
            problem = program_problem(words, programs.project)
            if problem:
                problems.append(f"{where}: {problem}")
                continue
            # the project's command with its wrappers gone, checked as test_docs_commands checks every doc
            for command in doc_commands.commands_in(shlex.join(words), where, programs.project):
                problems.extend(doc_commands.problems_of(command, programs))
    return problems


def url_problems(text: str, rig_file: Path) -> list[str]:
    """Every rig and sink URL on the page that its backend refuses (a URL with ``...`` in it is a pattern)."""
    import drivers
    from firmware_host.sinks.registry import sink_class

    problems = []
    for url in sorted(set(URL.findall(text))):
        if "..." in url or "<" in url or url.endswith("://"):
            continue  # a pattern, or the scheme named in prose (`opencv://` needs one)
        scheme = url.split("://", 1)[0]
        try:
            if scheme in RIG_SCHEMES:
                drivers.create_rig_source(url.replace(DEVICE_RIG_FILE, str(rig_file)))  # parses; opens nothing
                continue
            # ghnerf-listen reads the sinks' udp:// and serial:// forms, udp://:PORT being every interface
            as_sink = re.sub(r"^udp://:", "udp://127.0.0.1:", url)
            sink_class(as_sink).from_url(as_sink, cameras=("left", "right"))
        except Exception as e:  # noqa: BLE001 - each backend's own error type says what is wrong
            problems.append(f"{url}: {type(e).__name__}: {e}")
    return problems


@pytest.fixture(scope="module")
def programs() -> doc_commands.Programs:
    return doc_commands.Programs(doc_commands.Project.read())


@pytest.fixture(scope="module")
def rig_file(tmp_path_factory) -> Path:
    from calibration.render import example_rig
    from ghnerf_runtime.rig_file import save_rig

    # at the size depthai:// streams by default (640x400), which a rig file must match: ghcal's example rig at 960x600
    # scaled whole (the same field of view, as a binned sensor mode gives)
    rig = example_rig()
    rig = dataclasses.replace(rig, cameras=tuple(c.resized(640, 400) for c in rig.cameras))
    path = tmp_path_factory.mktemp("rig") / "rig.json"
    save_rig(rig, path)
    return path


def test_the_page_is_linked_from_the_readme_and_the_daemon_doc():
    assert "docs/bring-up.md" in (REPO / "README.md").read_text(encoding="utf-8")
    daemon = (REPO / "docs" / "daemon.md").read_text(encoding="utf-8")
    checked = daemon[daemon.index("## How it was checked, and what was not"):]
    assert "docs/bring-up.md" in checked.split("\n## ", 1)[0]


def test_every_command_on_the_page_is_a_program_that_takes_its_options(programs):
    text = PAGE.read_text(encoding="utf-8")
    lines = sh_lines(text)
    assert len(lines) > 50, "the sh blocks were not read"
    ran = {words[0].rsplit("/", 1)[-1] for _, line in lines if not is_assignment(line) for words in commands(line)}
    # the page's programs, the hardware steps' included: a reader broken into reading nothing passes no test
    assert {"ghnerf-daemon", "ghnerf-demo", "ghnerf-listen", "ghcal", "install.sh", "systemctl"} <= ran, ran
    problems = page_problems(text, programs)
    assert not problems, "\n".join(problems)


def test_a_misspelled_program_option_or_subcommand_fails(programs):
    text = PAGE.read_text(encoding="utf-8")
    for right, wrong, said in [
        ("ghnerf-daemon --config /etc/ghnerf/daemon.json --validate-config",
         "ghnerf-deamon --config /etc/ghnerf/daemon.json --validate-config", "ghnerf-deamon: not a program"),
        ("--measure-floor >", "--measure-flor >", "unknown option --measure-flor"),
        ("ghcal solve --board", "ghcal solv --board", "unknown subcommand 'solv'"),
        ("systemctl show ghnerf", "sytemctl show ghnerf", "sytemctl: not a program"),
    ]:
        assert right in text, right
        problems = page_problems(text.replace(right, wrong, 1), programs)
        assert any(said in p for p in problems), (wrong, problems)


def test_every_url_on_the_page_parses_for_its_backend(rig_file):
    text = PAGE.read_text(encoding="utf-8")
    urls = set(URL.findall(text))
    assert {u.split("://", 1)[0] for u in urls} >= {"depthai", "opencv", "sim", "serial", "usb", "udp", "vmc"}
    problems = url_problems(text, rig_file)
    assert not problems, "\n".join(problems)
    assert url_problems(text.replace("?fps=30&width=640", "?fsp=30&width=640"), rig_file), "a bad option passed"


def test_the_page_config_passes_the_daemons_checks(rig_file):
    from firmware_host.daemon.cli import check_config
    from firmware_host.daemon.config import daemon_config_from_dict

    (config_text,) = [b for b in blocks(PAGE.read_text(encoding="utf-8"), "json")]
    raw = json.loads(config_text.replace(DEVICE_RIG_FILE, str(rig_file)))
    raw["estimator"]["session"]["model_dir"] = str(REPO / "models")  # /opt/ghnerf/models on the device
    check_config(daemon_config_from_dict(raw))  # the keys, the rig and sink URLs, the model folder


def test_the_config_check_rehearsal_runs_as_written(tmp_path):
    """The page's first rehearsal: the example config printed and checked, the model loaded (about 2 s)."""
    text = PAGE.read_text(encoding="utf-8")
    (block,) = [b for b in blocks(text, "sh") if b.startswith("# rehearse: the config check")]
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    shim = bin_dir / "ghnerf-daemon"  # this checkout's daemon, whatever the venv's console script points at
    shim.write_text(f"#!/bin/sh\nexec {shlex.quote(sys.executable)} -m firmware_host.daemon.cli \"$@\"\n")
    shim.chmod(0o755)
    (tmp_path / "models").symlink_to(REPO / "models")  # the repository root's, which the example config names
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "PYTHONPATH": str(REPO)}
    done = subprocess.run(["bash", "-e", "-c", block], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert "daemon.json: ok; model: " in done.stderr
    assert (tmp_path / "daemon.json").is_file()


def folders_written_unmade(block: str) -> list[str]:
    """The relative folders a shell redirection in ``block`` writes into that no ``mkdir -p`` of the block makes.

    Each rehearsal must run on its own after step 0: a reader who skips one (5a's needs socat) must not find the
    next one's ``> out/bringup/udp.json`` failing on a folder only the skipped block made."""
    made: set[str] = set()
    unmade: list[str] = []
    for line in block.splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        words = shlex.split(line, comments=True)
        if words[:2] == ["mkdir", "-p"]:
            made.update(w.rstrip("/") for w in words[2:])
        for operator, target in zip(words, words[1:]):
            folder = os.path.dirname(target)
            if operator in {">", ">>"} and folder and not os.path.isabs(folder) and folder not in made:
                unmade.append(f"{target} (no `mkdir -p {folder}` before it in its block)")
    return unmade


def test_every_folder_a_block_writes_into_is_made_in_that_block():
    text = PAGE.read_text(encoding="utf-8")
    sh_blocks = blocks(text, "sh")
    assert any("> out/bringup/" in b for b in sh_blocks), "the rehearsals' redirections were not read"
    problems = [p for b in sh_blocks for p in folders_written_unmade(b)]
    assert not problems, "\n".join(problems)
    assert folders_written_unmade("mkdir -p out/x\necho a > out/x/a.json\necho b > out/y/b.json") == [
        "out/y/b.json (no `mkdir -p out/y` before it in its block)"]
