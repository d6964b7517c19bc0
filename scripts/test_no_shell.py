"""No process is started through a shell anywhere in the stack (issue 36): a command line
built from a parameter, a service request or a path runs whatever that text says. Every
program is started with an argument vector: adroit::runProgram (adroit_core/run_program.h)
in C++, subprocess with a list and no shell=True in Python.

Scans the workspace's own C++ and Python sources (not build/, install/, log/) for the calls
that hand a string to a shell; the failure lists each file:line. The scanner itself is tested
on hand-written snippets.
"""
import os
import re

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, ".."))
SKIP_DIRS = {"build", "install", "log", ".git", "build-asan", "install-asan", "build-fuzz", "__pycache__"}
# A call of system() or popen(), not a variable so named: "SyntheticSystem system(rng)" is a
# declaration (an identifier before the name), "return system(cmd)" a call.
CPP = re.compile(r"(?<![\w.>])(?:(?:std)?::)?(system|popen)\s*\(")
DECLARATION = re.compile(r"\b(?!return\b)\w+[\s&*]+$")
PYTHON = re.compile(r"\bos\.(system|popen)\s*\(|\bshell\s*=\s*True|\bcommands\.getoutput\s*\(")
CPP_SUFFIXES = (".cpp", ".cc", ".h", ".hpp")


def is_python(path):
    if path.endswith(".py"):
        return True
    if os.path.splitext(path)[1]:
        return False
    try:
        with open(path, "rb") as f:
            return b"python" in f.readline()
    except OSError:
        return False


def calls_a_shell(code, pattern):
    for match in pattern.finditer(code):
        if pattern is CPP and DECLARATION.search(code[:match.start()]):
            continue
        return True
    return False


def offending_lines(text, pattern):
    """1-based numbers of the lines that call a shell (comments skipped)."""
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        code = line.split("//", 1)[0] if pattern is CPP else line.split("#", 1)[0]
        if calls_a_shell(code, pattern):
            found.append(number)
    return found


def sources(root):
    for directory, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d not in SKIP_DIRS]
        for name in files:
            path = os.path.join(directory, name)
            if os.path.abspath(path) != os.path.abspath(__file__):  # this file names the calls
                yield path


def shell_calls(root):
    calls = []
    for path in sources(root):
        if path.endswith(CPP_SUFFIXES):
            pattern = CPP
        elif is_python(path):
            pattern = PYTHON
        else:
            continue
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        calls += ["%s:%d" % (os.path.relpath(path, root), n) for n in offending_lines(text, pattern)]
    return calls


def test_no_source_starts_a_program_through_a_shell():
    calls = shell_calls(ROOT)
    assert not calls, "started through a shell (use adroit::runProgram or a subprocess list): " + ", ".join(calls)


def test_scanner_finds_every_form():
    assert offending_lines('std::system(cmd.c_str());', CPP) == [1]
    assert offending_lines('x;\nFILE* p = popen(c, "r");', CPP) == [2]
    assert offending_lines('if (system("ls")) {}', CPP) == [1]
    assert offending_lines('  return system(cmd);', CPP) == [1]
    assert offending_lines('::popen(cmd, "r");', CPP) == [1]
    assert offending_lines('os.system("ls")', PYTHON) == [1]
    assert offending_lines('subprocess.run(cmd, shell=True)', PYTHON) == [1]
    assert offending_lines('os.popen("ls")', PYTHON) == [1]


def test_scanner_leaves_other_code_alone():
    assert offending_lines('const SyntheticSystem system(rng);', CPP) == []
    assert offending_lines('Plant& system(plants[0]);', CPP) == []
    assert offending_lines('robot.system(x);', CPP) == []
    assert offending_lines('adroit::runProgram({"python3", script});', CPP) == []
    assert offending_lines('// no std::system here', CPP) == []
    assert offending_lines('subprocess.run(["ls", path], check=True)', PYTHON) == []
    assert offending_lines('# os.system is not used', PYTHON) == []
