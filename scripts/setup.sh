#!/usr/bin/env bash
# Set up mitpiv on a fresh Debian/Ubuntu machine with Python >= 3.11:
#  1. create .venv (reused on later runs) and install mitpiv with its test and docs extras;
#  2. make sure Dr.Jit's LLVM backend finds LLVM >= 16: if not, install Debian's
#     libllvm19 when root, else print the exact command to run.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    echo "[setup] creating .venv with $($PY --version)"
    $PY -m venv .venv
fi
stamp=.venv/.mitpiv-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "[setup] installing mitpiv and dependencies into .venv"
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -e ".[test,docs]"
    # the peer trackers the tracking study and its tests run (the `peers` extra): openlpt's
    # declared GUI dependencies include opencv-python, which would shadow
    # opencv-python-headless, so both are installed without their dependencies (their
    # runtime needs, numpy and pyyaml, are already there)
    .venv/bin/python -m pip install -q --no-deps "openlpt==2.2.*" "optv==0.3.*"
    touch "$stamp"
fi
llvm_ok() {
    .venv/bin/python - <<'PY'
import sys
import drjit as dr
try:
    v = tuple(dr.detail.llvm_version())
except Exception:
    v = ()
print("[setup] Dr.Jit loads LLVM", ".".join(map(str, v)) or "none")
sys.exit(0 if v and v[0] >= 16 else 1)
PY
}
if ! llvm_ok; then
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
        echo "[setup] installing Debian's libllvm19 (Dr.Jit needs LLVM >= 16)"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null
        llvm_ok || { echo "[setup] Dr.Jit still does not find LLVM >= 16; set DRJIT_LIBLLVM_PATH"; exit 1; }
    else
        echo "[setup] Dr.Jit needs LLVM >= 16. Run: sudo apt-get install libllvm19"
        echo "        (or set DRJIT_LIBLLVM_PATH to a libLLVM.so of version >= 16), then re-run."
        exit 1
    fi
fi
echo "[setup] ready"
