# Sourced by tests/openssl_env.sh and tests/vulkan_env.sh: `eqa_apt_install WHAT PACKAGE...` installs
# Debian packages the tests need (as root with apt-get, else through sudo) and, when it cannot, says
# what to install and returns 1. WHAT says what they are for.
eqa_apt_install() {
  local what=$1 sudo=()
  shift
  echo "equiarm: installing $* ($what)" >&2
  if [ "$(id -u)" != 0 ]; then sudo=(sudo -n); fi
  if ! command -v apt-get >/dev/null \
    || ! { "${sudo[@]}" apt-get update -qq && DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends "$@" >/dev/null; }; then
    echo "equiarm: could not install $* (needs apt-get as root or passwordless sudo): install them ($what) by other means" >&2
    return 1
  fi
}
