# Sourced by tests/run_all.sh (and usable alone): makes sure OpenSSL's headers and pkg-config are
# there for the build (openssl-sys: DDS Security's keystores and RustDDS's security plugins link the
# system OpenSSL, docs/security.md), installing Debian's `libssl-dev` and `pkg-config` if missing, and
# the `openssl` command (tests/openssl_keystore.sh makes a keystore with it).
source "$(dirname "${BASH_SOURCE[0]}")/apt_install.sh"
if ! command -v pkg-config >/dev/null || ! pkg-config --exists openssl 2>/dev/null; then
  eqa_apt_install "OpenSSL's headers and pkg-config for the build" libssl-dev pkg-config || { return 1 2>/dev/null || exit 1; }
fi
if ! command -v openssl >/dev/null; then
  eqa_apt_install "the openssl command, for a keystore made by hand in the tests" openssl || { return 1 2>/dev/null || exit 1; }
fi
