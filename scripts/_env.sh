# Shared set-up for scripts/demo and scripts/test: a project virtualenv with coolmuscle
# installed from this checkout.  Idempotent: re-running skips what is already done.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${COOLMUSCLE_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"

need_python() {
    "$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' || {
        echo "coolmuscle needs Python 3.11 or newer ($PY is $("$PY" --version 2>&1))" >&2
        exit 1
    }
}

apt_install() {  # apt_install CMD:PACKAGE ...  installs PACKAGE when CMD is missing
    local missing=()
    for pair in "$@"; do
        command -v "${pair%%:*}" >/dev/null 2>&1 || missing+=("${pair#*:}")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    local sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    echo "installing Debian packages: ${missing[*]}"
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
}

need_compiler() {  # gcc and the interpreter's headers: pip compiles the hot modules with them
    [ "${COOLMUSCLE_COMPILE:-}" = "0" ] && return 0
    command -v gcc >/dev/null 2>&1 || apt_install gcc:gcc
    local inc
    inc="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_path("include"))')"
    if [ ! -f "$inc/Python.h" ]; then
        local ver
        ver="$("$VENV/bin/python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
        apt_install "python${ver}-config:python${ver}-dev"
    fi
}

pip_install() {  # pip_install ARGS...   quiet, its output added to $VENV/pip.log
    if ! "$VENV/bin/python" -m pip install "$@" >>"$VENV/pip.log" 2>&1; then
        tail -n 30 "$VENV/pip.log" >&2
        echo "pip install failed; the whole log is $VENV/pip.log" >&2
        exit 1
    fi
}

venv_install() {  # venv_install EXTRAS   (e.g. "" or "test")
    # An editable install: the build compiles the model's hot modules with mypyc beside
    # their sources in src/coolmuscle/ (setup.py, docs/performance.md "Compiled hot
    # modules").  Once a hot module changes (an edit, a git pull), its build stamp is
    # refused and the sources run: then the package is installed again, which compiles
    # them again (or only records the new times when the bytes are the same).
    need_python
    [ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV"
    need_compiler
    local spec="$ROOT" stamp="$VENV/.coolmuscle-installed-$1"
    [ -n "$1" ] && spec="$ROOT[$1]"
    local digest
    digest="$(cat "$ROOT/pyproject.toml" "$ROOT/setup.py" | sha256sum | cut -c1-16)"
    if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$digest" ]; then
        echo "installing coolmuscle${1:+ [$1]} into $VENV, compiling its hot modules (log: $VENV/pip.log)"
        : > "$VENV/pip.log"
        pip_install --upgrade pip
        pip_install -e "$spec"
        echo "$digest" > "$stamp"
    elif [ "${COOLMUSCLE_COMPILE:-}" != "0" ] \
            && ! "$VENV/bin/python" -m coolmuscle.tools.accel status >/dev/null 2>&1; then
        echo "compiling the hot modules again: $("$VENV/bin/python" -m coolmuscle.tools.accel status 2>&1)"
        : > "$VENV/pip.log"
        pip_install --no-deps -e "$spec"
    fi
    "$VENV/bin/python" -m coolmuscle.tools.accel status >/dev/null 2>&1 || \
        echo "note: $("$VENV/bin/coolmuscle" --version | tail -n 1) - slower" >&2
}
