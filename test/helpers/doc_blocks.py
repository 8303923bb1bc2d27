"""The shell blocks of README.md and docs/*.md, and how the suite checks them.

A ```bash (or ```sh) block runs as written, in order with the page's other runnable blocks,
from a copy of the checkout's layout in a temporary folder (the checkout's entries linked,
outputs written beside them, ../shared/data linked to the real data). An HTML comment on
the line before the block says otherwise:

- `<!-- not-run: REASON -->`: not run here (a ROS workspace, a browser, a GPU, ...);
- `<!-- flags-only: REASON -->`: every `monet ...` command's options must be in its
  `--help` (placeholders such as REC, or a run too long for the suite), every `-p name:=`
  of `ros2 run monet_ros NODE` a parameter in config/NODE.yaml and every `name:=` of
  `ros2 launch monet_ros pipeline.launch.py` a launch argument.
"""
from dataclasses import dataclass
import re
import shlex

FENCE = re.compile(r'^```(\w*)\s*$')
MARK = re.compile(r'^<!--\s*(not-run|flags-only)\s*:\s*(.+?)\s*-->\s*$')
SHELLS = {'bash', 'sh', 'shell'}
# `monet` subcommands whose first positional is a sub-subcommand
NESTED = {'labels': {'import'}, 'import': {'videos'}}


@dataclass(frozen=True)
class Block:
    path: str          # file, relative to the checkout
    line: int          # 1-based line of the opening fence
    kind: str          # 'run', 'not-run' or 'flags-only'
    reason: str
    text: str

    def where(self):
        return f'{self.path}:{self.line}'


def shell_blocks(path, relative):
    """Every shell block of the Markdown file `path` (Path), with its marker."""
    lines = path.read_text().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        fence = FENCE.match(lines[i])
        if not fence:
            i += 1
            continue
        start, language = i, fence.group(1)
        i += 1
        body = []
        while i < len(lines) and not lines[i].startswith('```'):
            body.append(lines[i])
            i += 1
        i += 1
        if language not in SHELLS:
            continue
        previous = next((t for t in reversed(lines[:start]) if t.strip()), '')
        mark = MARK.match(previous.strip())
        kind, reason = (mark.group(1), mark.group(2)) if mark else ('run', '')
        blocks.append(Block(relative, start + 1, kind, reason, '\n'.join(body) + '\n'))
    return blocks


def commands(text):
    """The block's commands: continuation lines joined, comments and blank lines dropped,
    each split into words (shlex, `#` comments removed)."""
    joined = re.sub(r'\\\n', ' ', text)
    out = []
    for line in joined.splitlines():
        if not line.strip() or line.lstrip().startswith('#'):
            continue
        out.append(shlex.split(line, comments=True))
    return out


def option_words(words):
    """The --options of one command's words, up to --ros-args (`[--rig RIG]` counts)."""
    found = []
    for word in words:
        word = word.strip('[]')
        if word == '--ros-args':
            break
        if word.startswith('--') and len(word) > 2:
            found.append(word.split('=', 1)[0])
    return found


def monet_invocation(words):
    """(subcommand words, the rest) of a `monet ...` command in `words`, else None. Finds
    `monet`, `.venv/bin/monet`, `python -m monet_ros.cli` and `torchrun ... -m
    monet_ros.cli`; a `ros2 run monet_ros monet` too."""
    for k, word in enumerate(words):
        if word == 'monet' or word.endswith('/monet') or word == 'monet_ros.cli':
            rest = words[k + 1:]
            if not rest or rest[0].startswith('-'):
                return [], rest
            sub = [rest[0]]
            if rest[0] in NESTED and len(rest) > 1 and rest[1] in NESTED[rest[0]]:
                sub.append(rest[1])
            return sub, rest[len(sub):]
    return None


def ros_parameters(words):
    """`(node, [parameter names])` of a `ros2 run monet_ros NODE ... -p name:=value` or
    `(launch file, [argument names])` of `ros2 launch monet_ros FILE name:=value`."""
    if words[:3] == ['ros2', 'run', 'monet_ros'] and len(words) > 3:
        names = [words[k + 1].split(':=')[0] for k in range(len(words) - 1)
                 if words[k] == '-p']
        return ('node', words[3], names)
    if words[:3] == ['ros2', 'launch', 'monet_ros'] and len(words) > 3:
        names = [w.strip('[]').split(':=')[0] for w in words[4:] if ':=' in w]
        return ('launch', words[3], names)
    return None
