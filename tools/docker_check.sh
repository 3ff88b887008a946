#!/usr/bin/env bash
# The Docker image, built and run: from the committed HEAD in a clean clone, `docker build`,
# then the image's default command (`make demo`, reports/ mounted) and, with --tests,
# `make test` in it. Prints a table of the results and leaves the logs and the demo's report
# in reports/docker_check_<time>/.
#
# usage: tools/docker_check.sh [--tests] [--make-base] [-h]
#   --tests       also run `make test` in the image (about 15 min on 2 cores); or DOCKER_CHECK_TESTS=1
#   --make-base   where the Dockerfile's base image is neither here nor pullable (no Docker Hub),
#                 build a stand-in for it from Debian packages with mmdebstrap (the recipe
#                 printed when it is missing)
#
# exit codes: 0 every step passed; 1 a step failed; 2 usage error;
#             77 skipped: no Docker engine answers (`docker info`);
#             78 skipped: the base image is missing and cannot be pulled (the recipe is printed).
#
# environment:
#   DOCKER_CHECK_TESTS=1        as --tests
#   DOCKER_CHECK_TEST_ARGS      words after `make test`, e.g. 'PYTEST_ARGS=tests/test_docker.py'
#   DOCKER_CHECK_IMAGE          the image's tag (default mecanum_robot:check)
#   DOCKER_CHECK_OUT            the folder of the logs and the demo's report
#                               (default reports/docker_check_<time>)
#   DOCKER_CHECK_BUILD_NETWORK  network of `docker build` (default host: the build reaches the
#                               package indexes through the host's network settings, as on
#                               machines whose DNS or proxy Docker's bridge does not get;
#                               "default" for Docker's own)
#   DOCKER_CHECK_RUN_NETWORK    network of the demo and test containers (default bridge: they
#                               need no network, and their ROS domain leases, lock files in the
#                               container's /tmp, do not see the host's, so on the host's
#                               network their DDS traffic could meet ROS runs on the host)
#   DOCKER                      the docker command (default docker)
#
# Nothing is downloaded but the base image (if pullable) and what the Dockerfile installs
# (Debian packages, the pinned wheels).
set -uo pipefail

DOCKER=${DOCKER:-docker}
IMAGE=${DOCKER_CHECK_IMAGE:-mecanum_robot:check}
BUILD_NETWORK=${DOCKER_CHECK_BUILD_NETWORK:-host}
RUN_NETWORK=${DOCKER_CHECK_RUN_NETWORK:-bridge}
TESTS=${DOCKER_CHECK_TESTS:-0}
MAKE_BASE=0
EXIT_FAILED=1
EXIT_USAGE=2
EXIT_NO_DOCKER=77
EXIT_NO_BASE=78

usage() {
    sed -n '2,/^set -uo pipefail/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'
}

say() { printf 'docker-check: %s\n' "$*"; }

network_args() {  # the options of docker build/run for a network; docker's own default needs none
    [ "$1" = default ] && return
    printf '%s\n' "--network=$1"
}

while [ $# -gt 0 ]; do
    case $1 in
        --tests) TESTS=1 ;;
        --make-base) MAKE_BASE=1 ;;
        -h | --help) usage; exit 0 ;;
        *) say "unknown argument: $1" >&2; usage >&2; exit "$EXIT_USAGE" ;;
    esac
    shift
done
case $TESTS in 0 | '' | no | false) TESTS=0 ;; *) TESTS=1 ;; esac
mapfile -t BUILD_NET < <(network_args "$BUILD_NETWORK")
mapfile -t RUN_NET < <(network_args "$RUN_NETWORK")

# --- a Docker engine? -------------------------------------------------------------------
if ! command -v "$DOCKER" > /dev/null 2>&1; then
    say "SKIPPED: no '$DOCKER' command here; install Docker to build and run the image"
    exit "$EXIT_NO_DOCKER"
fi
if ! info_error=$("$DOCKER" info 2>&1 > /dev/null); then
    say "SKIPPED: no Docker engine answers ('$DOCKER info' failed):"
    printf '  %s\n' "$info_error" | head -n 3
    exit "$EXIT_NO_DOCKER"
fi

# Under cgroup v1, all of Docker's containers weigh for the CPU as much as one process of the
# host (the docker cgroup's cpu.shares, 1024, against each host task's 1024): on a busy host,
# a system of nodes in the container starts several times slower than on the host, and
# timing-sensitive tests fail there while they pass on the host.
DOCKER_SHARES=/sys/fs/cgroup/cpu/docker/cpu.shares
read -r LOAD _ < /proc/loadavg 2> /dev/null || LOAD=0
CORES=$(getconf _NPROCESSORS_ONLN 2> /dev/null || echo 1)
if [ -r "$DOCKER_SHARES" ] && [ "$(cat "$DOCKER_SHARES")" -le 1024 ] \
        && awk -v load="$LOAD" -v cores="$CORES" 'BEGIN { exit !(load > cores) }'; then
    say "note: load average $LOAD on $CORES cores, and Docker's containers weigh for the CPU"
    say "  as one host process ($DOCKER_SHARES: $(cat "$DOCKER_SHARES")); timing-sensitive tests"
    say "  may starve in the image. As root, echo 8192 > $DOCKER_SHARES gives them a fair share."
fi

REPO=$(git -C "$(dirname "$0")" rev-parse --show-toplevel) || exit "$EXIT_FAILED"
HEAD=$(git -C "$REPO" rev-parse HEAD) || exit "$EXIT_FAILED"
SHORT=$(git -C "$REPO" rev-parse --short HEAD)
if [ -n "$(git -C "$REPO" status --porcelain --untracked-files=no)" ]; then
    say "note: the work tree has uncommitted changes; the image is built from HEAD ($SHORT) only"
fi

# --- the base image ---------------------------------------------------------------------
BASE=$(git -C "$REPO" show "$HEAD:Dockerfile" \
       | awk 'toupper($1) == "FROM" { for (i = 2; i <= NF; i++) if ($i !~ /^--/) { print $i; exit } }')
if [ -z "$BASE" ]; then
    say "FAILED: no FROM line in the Dockerfile at $SHORT"
    exit "$EXIT_FAILED"
fi

print_base_recipe() {
    cat << EOF
The base image $BASE is not here and cannot be pulled (Docker Hub unreachable?).
On a Debian bookworm machine, a stand-in made from Debian packages (Debian's Python 3.11,
not the official image's exact release, same Debian release) is:

mmdebstrap --variant=minbase --include=python3,python3-venv,python3-dev,python3-pip,ca-certificates \\
  bookworm /tmp/base.tar
docker import /tmp/base.tar debian-py:raw
mkdir -p /tmp/ctx && cp /etc/ssl/certs/ca-certificates.crt /tmp/ctx/ && cat > /tmp/ctx/Dockerfile <<'EOT'
FROM debian-py:raw
COPY ca-certificates.crt /etc/ssl/certs/ca-certificates.crt
ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
EOT
docker build --network host -t $BASE /tmp/ctx

or run this check with --make-base (make docker-check DOCKER_CHECK_ARGS=--make-base),
which does the same.
EOF
}

make_base() {
    # The stand-in: Debian bookworm's python3 with venv, headers and pip; the machine's CA
    # bundle, so that pip in the build trusts the index as the host does.
    if ! [[ $BASE =~ ^python:3\.11(\.[0-9]+)?-slim-bookworm$ ]]; then
        say "--make-base makes a stand-in for python:3.11.*-slim-bookworm only, not $BASE"
        return 1
    fi
    if ! command -v mmdebstrap > /dev/null 2>&1; then
        say "--make-base needs mmdebstrap (apt-get install mmdebstrap)"
        return 1
    fi
    local dir bundle=/etc/ssl/certs/ca-certificates.crt status=1
    dir=$(mktemp -d "${TMPDIR:-/tmp}/docker_check_base.XXXXXX") || return 1
    mkdir "$dir/ctx"
    {
        echo 'FROM debian-py:raw'
        echo 'LABEL org.opencontainers.image.description="stand-in from tools/docker_check.sh --make-base: Debian bookworm python3"'
        if [ -f "$bundle" ]; then
            cp "$bundle" "$dir/ctx/"
            echo 'COPY ca-certificates.crt /etc/ssl/certs/ca-certificates.crt'
            echo 'ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt'
        fi
        echo 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin'
    } > "$dir/ctx/Dockerfile"
    say "making a stand-in for $BASE from Debian bookworm packages (mmdebstrap, about a minute)"
    if mmdebstrap --quiet --variant=minbase \
            --include=python3,python3-venv,python3-dev,python3-pip,ca-certificates \
            bookworm "$dir/base.tar" \
        && "$DOCKER" import "$dir/base.tar" debian-py:raw > /dev/null \
        && "$DOCKER" build --quiet "${BUILD_NET[@]}" -t "$BASE" "$dir/ctx" > /dev/null
    then
        status=0
    fi
    rm -rf "$dir"
    return "$status"
}

if ! "$DOCKER" image inspect "$BASE" > /dev/null 2>&1; then
    say "pulling the base image $BASE"
    if ! pull_error=$("$DOCKER" pull --quiet "$BASE" 2>&1); then
        printf '  %s\n' "$pull_error" | tail -n 2
        if [ "$MAKE_BASE" = 1 ]; then
            make_base || { say "FAILED: could not make the stand-in base image"; exit "$EXIT_FAILED"; }
        else
            print_base_recipe
            say "SKIPPED: no base image $BASE"
            exit "$EXIT_NO_BASE"
        fi
    fi
fi
# The official image sets PYTHON_VERSION; a Debian stand-in does not.
BASE_PYTHON=$("$DOCKER" image inspect -f '{{range .Config.Env}}{{println .}}{{end}}' "$BASE" \
              | sed -n 's/^PYTHON_VERSION=//p')
BASE_NOTE=${BASE_PYTHON:+"Python $BASE_PYTHON"}
BASE_NOTE=${BASE_NOTE:-"no PYTHON_VERSION: a Debian stand-in, not the official image"}

# --- a clean clone of HEAD --------------------------------------------------------------
OUT=${DOCKER_CHECK_OUT:-"$REPO/reports/docker_check_$(date +%Y%m%d_%H%M%S)"}
WORK=$(mktemp -d "${TMPDIR:-/tmp}/docker_check.XXXXXX") || exit "$EXIT_FAILED"
trap 'rm -rf "$WORK"' EXIT
mkdir -p "$OUT/reports" || exit "$EXIT_FAILED"
# The container's user (uid 1000 unless built otherwise) writes the demo's report here.
chmod a+rwx "$OUT/reports"
if ! git clone --quiet --no-checkout "$REPO" "$WORK/clone" \
        || ! git -C "$WORK/clone" checkout --quiet --detach "$HEAD"; then
    say "FAILED: could not clone $REPO at $SHORT"
    exit "$EXIT_FAILED"
fi
say "image $IMAGE from $SHORT (clean clone), base $BASE ($BASE_NOTE); logs in ${OUT#"$REPO"/}/"

seconds_since() { echo $(($(date +%s) - $1)); }

show_tail() {  # the end of a failed step's log
    say "the last lines of $1:"
    tail -n 25 "$1" | sed 's/^/  | /'
}

ROWS=()
FAILED=0
row() { ROWS+=("$(printf '%-6s %-62s %6s s' "$1" "$2" "$3")"); }

# --- build ------------------------------------------------------------------------------
say "building (docker build ${BUILD_NET[*]} -t $IMAGE .) ..."
start=$(date +%s)
"$DOCKER" build "${BUILD_NET[@]}" -t "$IMAGE" "$WORK/clone" > "$OUT/build.log" 2>&1
build_status=$?
build_s=$(seconds_since "$start")
if [ "$build_status" = 0 ]; then
    row build "ok" "$build_s"
else
    row build "FAILED (exit $build_status), see build.log" "$build_s"
    show_tail "$OUT/build.log"
    FAILED=1
fi

# --- make demo (the image's default command) --------------------------------------------
if [ "$FAILED" = 0 ]; then
    say "running the demo (docker run -v reports:/work/reports $IMAGE) ..."
    start=$(date +%s)
    "$DOCKER" run --rm "${RUN_NET[@]}" -v "$OUT/reports:/work/reports" \
        "$IMAGE" > "$OUT/demo.log" 2>&1
    demo_status=$?
    demo_s=$(seconds_since "$start")
    # e.g. "demo: PASS: 12 of 12 goals reached, 0 collisions, 47.33 m in ..."
    verdict=$(sed -n 's/^demo: \(PASS\|FAIL\): \([0-9]* of [0-9]* goals reached, [0-9]* collisions\).*/\1: \2/p' \
              "$OUT/demo.log" | tail -n 1)
    if [ "$demo_status" = 0 ] && [ "${verdict%%:*}" = PASS ]; then
        row demo "$verdict" "$demo_s"
    else
        row demo "FAILED (exit $demo_status) ${verdict:-no verdict}, see demo.log" "$demo_s"
        show_tail "$OUT/demo.log"
        FAILED=1
    fi
    # What the container's user wrote, removable by whoever runs this check.
    "$DOCKER" run --rm --network=none -v "$OUT/reports:/work/reports" --entrypoint chmod \
        "$IMAGE" -R a+rwX /work/reports > /dev/null 2>&1
fi

# --- make test --------------------------------------------------------------------------
if [ "$FAILED" = 0 ] && [ "$TESTS" = 1 ]; then
    read -r -a test_args <<< "${DOCKER_CHECK_TEST_ARGS:-}"
    say "running the tests (docker run $IMAGE make test${test_args[*]:+ ${test_args[*]}}) ..."
    start=$(date +%s)
    "$DOCKER" run --rm "${RUN_NET[@]}" "$IMAGE" make test "${test_args[@]}" \
        > "$OUT/test.log" 2>&1
    test_status=$?
    test_s=$(seconds_since "$start")
    # pytest's last line, e.g. "==== 2390 passed, 7 skipped in 812.35s (0:13:32) ===="
    counts=$(grep -E '^=+ .*\b(passed|failed|error|errors|skipped|no tests ran)\b.* in [0-9.]+s' \
             "$OUT/test.log" | tail -n 1 | sed -E 's/^=+ //; s/ in [0-9.]+s.*//')
    if [ "$test_status" = 0 ]; then
        row tests "${counts:-passed}" "$test_s"
    else
        row tests "FAILED (exit $test_status) ${counts:-no summary}, see test.log" "$test_s"
        grep -E '^(FAILED|ERROR) ' "$OUT/test.log" | head -n 20 | sed 's/^/  /'
        FAILED=1
    fi
elif [ "$TESTS" = 0 ]; then
    row tests "not run (--tests or DOCKER_CHECK_TESTS=1)" "-"
fi

# --- the table --------------------------------------------------------------------------
echo
printf '%-6s %-62s %8s\n' step result time
printf '%s\n' "${ROWS[@]}"
echo
if [ "$FAILED" = 0 ]; then
    say "PASSED: image $IMAGE from $SHORT; logs and the demo's report in ${OUT#"$REPO"/}/"
    exit 0
fi
say "FAILED: logs in ${OUT#"$REPO"/}/"
exit "$EXIT_FAILED"
