# Sourced by tests/run_all.sh (and usable alone): makes sure OpenSSL's headers and pkg-config are
# there for the build (openssl-sys: DDS Security's keystores and RustDDS's security plugins link the
# system OpenSSL, docs/security.md). Installs Debian's `libssl-dev` and `pkg-config` when missing: as
# root with apt-get, else through sudo; says what to install otherwise.
if ! command -v pkg-config >/dev/null || ! pkg-config --exists openssl 2>/dev/null; then
  echo "equiarm: installing OpenSSL's headers and pkg-config (libssl-dev, pkg-config) for the build" >&2
  _sudo=()
  if [ "$(id -u)" != 0 ]; then _sudo=(sudo -n); fi
  if ! command -v apt-get >/dev/null \
    || ! { "${_sudo[@]}" apt-get update -qq && DEBIAN_FRONTEND=noninteractive "${_sudo[@]}" apt-get install -y -qq --no-install-recommends libssl-dev pkg-config >/dev/null; }; then
    echo "equiarm: could not install libssl-dev and pkg-config (needs apt-get as root or passwordless sudo): install OpenSSL's development files and pkg-config by other means" >&2
    return 1 2>/dev/null || exit 1
  fi
fi
unset _sudo
