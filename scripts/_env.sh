# Shared set-up for scripts/demo and scripts/test: a project virtualenv with coolmuscle
# installed from this checkout, at the versions of constraints.txt.  Idempotent:
# re-running skips what is already done.  One install stamp for both scripts
# ($VENV/.coolmuscle-install: what was installed, from which pyproject.toml, setup.py
# and constraints.txt): the test script adds its extras to what the demo installed and
# compiles nothing the demo compiled.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${COOLMUSCLE_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"
STAMP="$VENV/.coolmuscle-install"
STARTED=$SECONDS

say() {  # say TEXT   one line with the seconds since the script started
    printf '[%3d s] %s\n' "$((SECONDS - STARTED))" "$*"
}

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
    say "installing Debian packages: ${missing[*]}"
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
}

need_compiler() {  # gcc and the interpreter's headers: the build compiles the hot modules
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

pip_quiet() {  # pip_quiet ARGS...   its output added to $VENV/pip.log
    if ! "$VENV/bin/python" -m pip install "$@" >>"$VENV/pip.log" 2>&1; then
        tail -n 30 "$VENV/pip.log" >&2
        echo "pip install failed; the whole log is $VENV/pip.log" >&2
        exit 1
    fi
}

pip_showing_build() {  # pip_showing_build ARGS...   the compile's own lines shown as they come
    # pip -v passes the build's output on as it comes; the lines of setup.py's compile step
    # start with "coolmuscle build: " (what it is on, with its elapsed time), the rest
    # goes to the log
    if ! "$VENV/bin/python" -m pip install -v "$@" 2>&1 | tee -a "$VENV/pip.log" \
            | sed -un 's/^.*coolmuscle build: /    /p'; then
        tail -n 30 "$VENV/pip.log" >&2
        echo "pip install failed; the whole log is $VENV/pip.log" >&2
        exit 1
    fi
}

merge_extras() {  # merge_extras A B   the union of two comma-separated lists, sorted
    printf '%s\n' "${1//,/$'\n'}" "${2//,/$'\n'}" | sed '/^$/d' | sort -u | paste -sd, -
}

ACCEL_PID=""

compiled_current() {  # the compiled hot modules of the checkout are current
    "$VENV/bin/python" -m coolmuscle.tools.accel status >/dev/null 2>&1
}

wait_compile() {  # wait_compile   the background compile of venv_install ... background, shown
    [ -n "$ACCEL_PID" ] || return 0
    say "waiting for the compile of the hot modules (started in the background):"
    tail -n +1 -f --pid="$ACCEL_PID" "$VENV/accel-build.log" | sed -u 's/^/    /'
    wait "$ACCEL_PID" || true
    ACCEL_PID=""
}

venv_install() {  # venv_install EXTRAS [background]   (EXTRAS e.g. "all" or "all,test,docs,accel")
    # "background": when the hot modules must be compiled, install without compiling and
    # compile them in the background (`python -m coolmuscle.tools.accel build`, log in
    # $VENV/accel-build.log); the sources run until it ends; wait_compile waits for it.
    # An editable install with the build requirements in the venv itself (the accel
    # extra: no separate build environment to set up each time): the build compiles the
    # model's hot modules with mypyc beside their sources in src/coolmuscle/ (setup.py,
    # docs/performance.md "Compiled hot modules"), once.  When a hot module changes (an
    # edit, a git pull) its build stamp is refused and the sources run until
    # `python -m coolmuscle.tools.accel build` compiles them again, which this does.
    need_python
    if [ ! -x "$VENV/bin/python" ]; then
        say "creating $VENV"
        "$PY" -m venv "$VENV"
    fi
    need_compiler
    local digest wanted="$1" have="" have_digest=""
    digest="$(cat "$ROOT/pyproject.toml" "$ROOT/setup.py" "$ROOT/constraints.txt" \
        | sha256sum | cut -c1-16)"
    if [ -f "$STAMP" ]; then
        read -r have_digest have < "$STAMP" || true
    fi
    [ "$have_digest" = "$digest" ] || have=""
    local all
    all="$(merge_extras "$wanted" "$have")"
    local later=""
    if [ "${2:-}" = "background" ] && [ "${COOLMUSCLE_COMPILE:-}" != "0" ] \
            && ! compiled_current; then
        later=1                     # nothing current to keep: install without compiling
    fi
    if [ "$have_digest" != "$digest" ] || [ "$all" != "$have" ]; then
        : > "$VENV/pip.log"
        say "installing the build requirements (mypy, setuptools) into $VENV (log: $VENV/pip.log)"
        local build
        build="$("$VENV/bin/python" -c 'import sys, tomllib
print("\n".join(tomllib.load(open(sys.argv[1], "rb"))["build-system"]["requires"]))' \
            "$ROOT/pyproject.toml")"
        # shellcheck disable=SC2086  # one requirement a line, none with a space
        pip_quiet -c "$ROOT/constraints.txt" $build
        if [ -n "$later" ]; then
            say "installing coolmuscle [$all] and its dependencies (compiled afterwards)"
            COOLMUSCLE_COMPILE=0 pip_showing_build -c "$ROOT/constraints.txt" \
                --no-build-isolation -e "$ROOT[$all]" >/dev/null
        else
            say "installing coolmuscle [$all] and its dependencies; the build compiles the hot modules"
            pip_showing_build -c "$ROOT/constraints.txt" --no-build-isolation -e "$ROOT[$all]"
        fi
        echo "$digest $all" > "$STAMP"
    fi
    if [ -n "$later" ]; then
        say "compiling the hot modules in the background (log: $VENV/accel-build.log); the sources run until then"
        env -u COOLMUSCLE_COMPILE "$VENV/bin/python" -m coolmuscle.tools.accel build --quiet \
            > "$VENV/accel-build.log" 2>&1 &
        ACCEL_PID=$!
        return 0
    fi
    if [ "${COOLMUSCLE_COMPILE:-}" != "0" ] && ! compiled_current; then
        say "compiling the hot modules: $("$VENV/bin/python" -m coolmuscle.tools.accel status 2>&1)"
        "$VENV/bin/python" -m coolmuscle.tools.accel build --quiet 2>&1 | sed -u 's/^/    /' || true
    fi
    "$VENV/bin/python" -m coolmuscle.tools.accel status >/dev/null 2>&1 || \
        echo "note: $("$VENV/bin/coolmuscle" --version | tail -n 1) - slower" >&2
    say "ready: $("$VENV/bin/coolmuscle" --version | tail -n 1)"
}
