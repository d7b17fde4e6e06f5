#!/usr/bin/env bash
# Set up curate on a fresh machine (idempotent; a second run takes seconds).
#  1. a virtual environment: the active one ($VIRTUAL_ENV; .venv becomes a link to it), else ./.venv
#  2. Debian's libusb-1.0-0 for open3d (when root and missing)
#  3. torch: with an NVIDIA GPU the default index's (CUDA) build; without one PyTorch's own CPU
#     wheel index, falling back to the default index when that index cannot be reached
#  4. curate itself (editable) with its test tools; with --ray also Ray (only `curate batch --executor
#     ray` needs it: about 300 MB more)
# Afterwards run curate as .venv/bin/python -m curate (or activate .venv).
set -euo pipefail
cd "$(dirname "$0")/.."
EXTRAS="test"
for a in "$@"; do
  case "$a" in
    --ray) EXTRAS="test,ray" ;;
    *) echo "setup: unknown option $a (known: --ray)" >&2; exit 2 ;;
  esac
done
TORCH="torch==2.13.0"
CPU_INDEX="https://download.pytorch.org/whl/cpu"
step() { echo "setup: $*"; }

if [ -n "${VIRTUAL_ENV:-}" ]; then
  if [ "$(readlink -f .venv 2>/dev/null || true)" != "$(readlink -f "$VIRTUAL_ENV")" ]; then
    [ -e .venv ] && [ ! -L .venv ] && { echo "setup: .venv exists and is not the active environment $VIRTUAL_ENV; remove it or deactivate" >&2; exit 1; }
    ln -sfn "$VIRTUAL_ENV" .venv
  fi
  step "using the active virtual environment $VIRTUAL_ENV (.venv links to it)"
elif [ ! -x .venv/bin/python ]; then
  step "creating the virtual environment .venv"
  if ! "${PYTHON:-python3}" -m venv .venv; then
    echo "setup: python3 -m venv failed: install your Python's venv module (Debian/Ubuntu: apt-get install python3-venv)" >&2
    exit 1
  fi
else
  step "using the virtual environment .venv"
fi
PY=.venv/bin/python
PIP=("$PY" -m pip install -q --disable-pip-version-check)

if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && ! dpkg -s libusb-1.0-0 >/dev/null 2>&1; then
  step "installing Debian's libusb-1.0-0 (open3d needs it)"
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
fi

if "$PY" -c "import torch" 2>/dev/null; then
  step "torch $("$PY" -c 'import torch; print(torch.__version__)') already installed"
elif command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; then
  step "installing $TORCH (an NVIDIA GPU is present: the CUDA build)"
  "${PIP[@]}" "$TORCH"
else
  step "installing $TORCH, CPU build (no NVIDIA GPU)"
  if ! "${PIP[@]}" --timeout 5 --retries 0 --index-url "$CPU_INDEX" "$TORCH" 2>/dev/null; then
    step "PyTorch's CPU index cannot be reached: $TORCH from the default index"
    "${PIP[@]}" "$TORCH"
  fi
fi

WANT="$(sha256sum pyproject.toml | cut -c1-16)"
HAVE="$(cat .venv/.curate-setup 2>/dev/null || true)"
# up to date: the same pyproject.toml, and every extra asked for already there (Ray, once installed, stays)
if "$PY" -c "import curate, pytest, hypothesis, ruff" 2>/dev/null && "$PY" -m pip check -q >/dev/null 2>&1 \
   && [ "${HAVE%% *}" = "$WANT" ] && { [ "$EXTRAS" = "test" ] || "$PY" -c "import ray" 2>/dev/null; }; then
  step "curate and its test tools already installed"
else
  step "installing curate (editable) with its test tools$([ "$EXTRAS" = "test" ] || echo " and Ray")"
  "${PIP[@]}" -e ".[$EXTRAS]"
  echo "$WANT" > .venv/.curate-setup
fi
step "done: $("$PY" -m curate --version)"
