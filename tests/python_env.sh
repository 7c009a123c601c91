# Sourced by tests/run_all.sh and the bench scripts: creates (once) and activates the Python virtual
# environment holding the pinned third-party peers of tests/python/requirements.txt, and exports
# EQUIARM_PYTHON. The environment lives outside the clone, keyed by the requirements' hash, so fresh
# clones on the same machine reuse it. Override its parent folder with EQUIARM_VENV_DIR.

# EQUIARM_REQUIREMENTS picks another requirements file (the benchmarks' peers).
_req="${EQUIARM_REQUIREMENTS:-$(git rev-parse --show-toplevel 2>/dev/null || pwd)/tests/python/requirements.txt}"
_hash=$(sha256sum "$_req" | cut -c1-16)
_venv="${EQUIARM_VENV_DIR:-$HOME/.cache/equiarm/venvs}/py-$_hash"
if [ ! -f "$_venv/.complete" ]; then
  echo "equiarm: creating the test Python environment in $_venv" >&2
  rm -rf "$_venv"
  python3 -m venv "$_venv"
  if ! "$_venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$_req"; then
    echo "equiarm: installing $_req into $_venv failed (above); nothing is kept" >&2
    rm -rf "$_venv"
    return 1
  fi
  touch "$_venv/.complete"
fi
export EQUIARM_PYTHON="$_venv/bin/python"
unset _req _hash _venv
