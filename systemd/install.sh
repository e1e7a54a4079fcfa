#!/usr/bin/env bash
# Install the ghnerf daemon as a systemd service on the device, from this checkout.
#
#   sudo systemd/install.sh                      # /opt/ghnerf, enable and start ghnerf.service
#   sudo systemd/install.sh --prefix /srv/ghnerf --no-start
#   systemd/install.sh --destdir /tmp/stage      # stage the files only (an image build; no root)
#
# What it does: a virtual environment with the runtime only (no PyTorch) at PREFIX/venv, pinned by
# constraints.txt; the models and docs under PREFIX; the unit file, the udev rules and, when none is
# there yet, /etc/ghnerf/daemon.json and 61-ghnerf-local.rules (yours: never overwritten); a system user
# `ghnerf` in plugdev, dialout and video; the config checked with --validate-config against the new
# environment and models (the model loaded, as the start does), the previous ones put back if it fails;
# then systemd and udev reloaded and the service enabled and started.
# docs/daemon.md has the details.
set -euo pipefail

PREFIX=/opt/ghnerf
DESTDIR=
PYTHON=${PYTHON:-python3.11}
START=1
VENV=1

die() { echo "install.sh: error: $*" >&2; exit 2; }
usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; exit "${1:-0}"; }

while [ $# -gt 0 ]; do
    case "$1" in
        --prefix) [ $# -ge 2 ] || die "--prefix needs a folder"; PREFIX=$2; shift 2 ;;
        --destdir) [ $# -ge 2 ] || die "--destdir needs a folder"; DESTDIR=$2; shift 2 ;;
        --python) [ $# -ge 2 ] || die "--python needs an interpreter"; PYTHON=$2; shift 2 ;;
        --no-start) START=0; shift ;;
        -h|--help) usage 0 ;;
        *) echo "install.sh: error: unknown option $1" >&2; usage 2 ;;
    esac
done
case "$PREFIX" in /*) ;; *) die "--prefix must be an absolute path, got $PREFIX" ;; esac
case "$PREFIX" in *[!A-Za-z0-9/._-]*) die "--prefix may hold only letters, digits and / . _ -, got $PREFIX" ;; esac
# The unit runs from the prefix (WorkingDirectory, ExecStart) under ProtectHome=yes, which hides /home,
# /root and /run/user: a prefix there fails every start (status 200/CHDIR) until the start limit.
under_home() { case "$1/" in /home/*|/root/*|/run/user/*) return 0 ;; esac; return 1; }
if under_home "$(realpath -m -s "$PREFIX")" || { [ -z "$DESTDIR" ] && under_home "$(realpath -m "$PREFIX")"; }; then
    die "--prefix $PREFIX is under a home folder (/home, /root or /run/user), which the service's sandbox (ProtectHome=yes) hides: it could not start from there; pass a system folder, e.g. --prefix /opt/ghnerf"
fi

REPO=$(cd "$(dirname "$0")/.." && pwd)
ROOT=${DESTDIR%/}
if [ -n "$DESTDIR" ]; then
    # A virtual environment records its own absolute path: it cannot be built in a staging folder.
    VENV=0
    START=0
    mkdir -p "$DESTDIR"
elif [ "$(id -u)" != 0 ]; then
    die "run as root (or pass --destdir DIR to stage the files without installing them)"
fi
[ -f "$REPO/models/model_card.json" ] || die "no model in $REPO/models (make model builds it)"
[ -f "$REPO/constraints.txt" ] || die "$REPO/constraints.txt is missing: run from a full checkout"

echo "installing the ghnerf daemon from $REPO into ${ROOT}${PREFIX}"
install -d "$ROOT$PREFIX" "$ROOT$PREFIX/docs" "$ROOT/etc/ghnerf" "$ROOT/etc/systemd/system" "$ROOT/etc/udev/rules.d"

IN_PLACE=0
if [ "$(cd "$ROOT$PREFIX" && pwd -P)" = "$(cd "$REPO" && pwd -P)" ]; then
    echo "the checkout is the prefix: its models and docs are used in place"
    IN_PLACE=1
fi
# Models: replaced as a whole, so no graph of an older model is left beside the new ones. Copied to
# models.new first; swapped in only once the new environment is built and runs, just before the venv
# link is switched, so a failed build leaves the old models beside the old code. The replaced ones wait
# in models.old until the config validates against the new pair (restore_models puts them back).
stage_models() {
    [ "$IN_PLACE" = 0 ] || return 0
    rm -rf "$ROOT$PREFIX/models.new" && cp -R "$REPO/models" "$ROOT$PREFIX/models.new" \
        && chmod -R u+rwX,go+rX "$ROOT$PREFIX/models.new"  # a checkout cloned under umask 077: the service reads them
}
swap_models() {
    [ "$IN_PLACE" = 0 ] || return 0
    rm -rf "$ROOT$PREFIX/models.old"
    [ ! -e "$ROOT$PREFIX/models" ] || mv "$ROOT$PREFIX/models" "$ROOT$PREFIX/models.old"
    mv "$ROOT$PREFIX/models.new" "$ROOT$PREFIX/models"
}
restore_models() {
    [ "$IN_PLACE" = 0 ] && [ -e "$ROOT$PREFIX/models.old" ] || return 0  # a first install: nothing to put back
    rm -rf "$ROOT$PREFIX/models" && mv "$ROOT$PREFIX/models.old" "$ROOT$PREFIX/models"
}
keep_models() {
    [ "$IN_PLACE" = 0 ] || return 0
    rm -rf "$ROOT$PREFIX/models.old"
    cp "$REPO"/docs/*.md "$ROOT$PREFIX/docs/" && chmod go+r "$ROOT$PREFIX"/docs/*.md
}
# The config: yours once there (never overwritten); written before the check, which reads it.
write_config() {
    if [ -e "$ROOT/etc/ghnerf/daemon.json" ]; then
        echo "kept the existing $ROOT/etc/ghnerf/daemon.json"
    else
        sed "s|/opt/ghnerf|$PREFIX|g" "$REPO/systemd/daemon.json" > "$ROOT/etc/ghnerf/daemon.json"
        chmod 0644 "$ROOT/etc/ghnerf/daemon.json"
        echo "wrote $ROOT/etc/ghnerf/daemon.json: set its rig.url and sinks for this rig (docs/daemon.md)"
    fi
}

# udev: 60-ghnerf.rules is ours and replaced; 61-ghnerf-local.rules is the user's and written only when absent.
# Rules a user added to an installed 60-ghnerf.rules (its templates used to be there) move to the local file
# first: overwritten, a usb:// receiver lost its permissions and a serial one its stable name at the upgrade.
active_rules() { grep -v '^[[:space:]]*\(#\|$\)' "$1" || true; }
install_rules() {
    local dir="$ROOT/etc/udev/rules.d" added
    local ours="$dir/60-ghnerf.rules" local_rules="$dir/61-ghnerf-local.rules"
    [ -e "$local_rules" ] || install -m 0644 "$REPO/systemd/61-ghnerf-local.rules" "$local_rules"
    if [ -f "$ours" ]; then
        added=$(active_rules "$ours" | grep -vxF -f <(active_rules "$REPO/systemd/60-ghnerf.rules"; active_rules "$local_rules") || true)
        if [ -n "$added" ]; then
            printf '\n# moved here from 60-ghnerf.rules by install.sh (%s)\n%s\n' "$(date -u +%F)" "$added" >> "$local_rules"
            echo "moved $(printf '%s\n' "$added" | wc -l) rule(s) of yours from $ours to $local_rules"
        fi
    fi
    install -m 0644 "$REPO/systemd/60-ghnerf.rules" "$ours"
}

if [ -z "$DESTDIR" ]; then
    getent group plugdev >/dev/null || groupadd --system plugdev
    getent group dialout >/dev/null || groupadd --system dialout
    getent group video >/dev/null || groupadd --system video
    if ! id ghnerf >/dev/null 2>&1; then
        # its own group, or the one a partial install (or an image build) left: --user-group fails on that
        if getent group ghnerf >/dev/null; then own_group=(--gid ghnerf); else own_group=(--user-group); fi
        useradd --system --home-dir /var/lib/ghnerf --no-create-home --shell /usr/sbin/nologin \
            "${own_group[@]}" --groups plugdev,dialout,video ghnerf
    fi
fi

if [ "$VENV" = 1 ]; then
    # The environment links to the interpreter it is made from. The service cannot start one under a
    # home folder (ProtectHome=yes hides /home, /root and /run/user), nor one its user cannot read.
    INTERPRETER=$(readlink -f "$(command -v "$PYTHON" || echo "$PYTHON")")
    [ -x "$INTERPRETER" ] || die "no Python interpreter $PYTHON (pass --python /usr/bin/python3.11)"
    if under_home "$("$PYTHON" -c 'import sys, os; print(os.path.realpath(sys.base_prefix))')"; then
        die "$PYTHON lives under a home folder, which the service's sandbox hides; pass --python with a system interpreter, e.g. --python /usr/bin/python3.11"
    fi
    # A new environment beside the old one, switched to by renaming a link: a failed build (no network)
    # leaves the running service its working environment.
    NEW="venv-$(date -u +%Y%m%dT%H%M%S)"
    # never the name of one already there (a re-run within the second): a failed build removes its folder
    while [ -e "$PREFIX/$NEW" ]; do sleep 1; NEW="venv-$(date -u +%Y%m%dT%H%M%S)"; done
    "$PYTHON" -m venv "$PREFIX/$NEW" \
        || { rm -rf "${PREFIX:?}/$NEW"; die "$PYTHON could not make a virtual environment; the previous environment and models are kept"; }
    "$PREFIX/$NEW/bin/python" -m pip install --quiet --upgrade "pip>=24" \
        || { rm -rf "${PREFIX:?}/$NEW"; die "pip could not upgrade itself; the previous environment and models are kept"; }
    # The runtime only: onnxruntime, OpenCV, depthai, pyserial, pyusb, numpy (no [training] extra).
    "$PREFIX/$NEW/bin/python" -m pip install --quiet -c "$REPO/constraints.txt" "$REPO" \
        || { rm -rf "${PREFIX:?}/$NEW"; die "pip could not install the runtime; the previous environment and models are kept"; }
    runuser -u ghnerf -- "$PREFIX/$NEW/bin/python" -c "import firmware_host.daemon" \
        || { rm -rf "${PREFIX:?}/$NEW"; die "the service user ghnerf cannot run $INTERPRETER; pass --python with an interpreter every user can run, e.g. --python /usr/bin/python3.11"; }
    stage_models || { rm -rf "${PREFIX:?}/$NEW" "$PREFIX/models.new"; die "could not copy $REPO/models; the previous environment and models are kept"; }
    # The environment the link points to now (maybe an older one, after a rollback by relinking): kept.
    PREVIOUS=$(readlink "$PREFIX/venv" 2>/dev/null || true)
    PREVIOUS=${PREVIOUS%/}
    PREVIOUS=${PREVIOUS##*/}
    write_config
    swap_models
    [ -d "$PREFIX/venv" ] && [ ! -L "$PREFIX/venv" ] && mv "$PREFIX/venv" "$PREFIX/venv-before-links"
    ln -sfn "$NEW" "$PREFIX/venv.link" && mv -T "$PREFIX/venv.link" "$PREFIX/venv"
    # The check runs the new environment on the new models at the paths the config names, before anything
    # else of the install is in place: a config they cannot serve (a setting the new model lacks) puts the
    # previous environment and models back, so the running service's next restart still starts.
    if ! runuser -u ghnerf -- "$PREFIX/venv/bin/ghnerf-daemon" --config /etc/ghnerf/daemon.json --validate-config >/dev/null; then
        restore_models
        if [ -d "$PREFIX/venv-before-links" ]; then
            rm -f "$PREFIX/venv" && mv "$PREFIX/venv-before-links" "$PREFIX/venv" && rm -rf "${PREFIX:?}/$NEW"
        elif [ -n "$PREVIOUS" ] && [ -d "$PREFIX/$PREVIOUS" ]; then
            ln -sfn "$PREVIOUS" "$PREFIX/venv.link" && mv -T "$PREFIX/venv.link" "$PREFIX/venv" && rm -rf "${PREFIX:?}/$NEW"
        fi  # else a first install: nothing to put back, nothing started
        die "/etc/ghnerf/daemon.json does not validate with the new environment and models (message above); the previous environment and models are kept; fix the config (or the models) and run install.sh again"
    fi
    keep_models
    # keep the environment just replaced (to roll back by relinking) and the new one; remove the others
    for old in "$PREFIX"/venv-2*; do
        [ -e "$old" ] || continue
        case "${old##*/}" in "$NEW"|"$PREVIOUS") continue ;; esac
        rm -rf "$old"
    done
    rm -rf "$PREFIX/venv-before-links"
else
    write_config
    stage_models
    swap_models
    keep_models
fi

sed "s|/opt/ghnerf|$PREFIX|g" "$REPO/systemd/ghnerf.service" > "$ROOT/etc/systemd/system/ghnerf.service"
chmod 0644 "$ROOT/etc/systemd/system/ghnerf.service"
install_rules

# Run here, or printed for the device: restart (not enable --now), so an upgraded, running service
# picks up the new environment, and the udev rules reloaded for an OAK already plugged in.
START_COMMANDS=(
    "systemctl daemon-reload"
    "udevadm control --reload-rules"
    "udevadm trigger --subsystem-match=usb"
    "systemctl enable ghnerf.service"
    "systemctl restart ghnerf.service"
)
if [ "$START" = 1 ]; then
    for command in "${START_COMMANDS[@]}"; do
        $command  # plain words, split on purpose
    done
    systemctl --no-pager --lines=5 status ghnerf.service || true
else
    hint=$(printf ' && %s' "${START_COMMANDS[@]}")
    if [ -n "$DESTDIR" ]; then
        # Staged, the unit names an environment and a user that are not there: those commands alone would
        # start a service that fails at once (203/EXEC, 217/USER) and restarts until its start limit.
        echo "staged only: no environment $PREFIX/venv (the unit runs $PREFIX/venv/bin/ghnerf-daemon) and no user" \
            "ghnerf (groups plugdev, dialout, video): the service cannot start without them; make them on the" \
            "device with: sudo systemd/install.sh --prefix $PREFIX --no-start"
    fi
    echo "not started; on the device: ${hint# && }"
fi
