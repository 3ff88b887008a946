# The workspace in a container, set up the way the README's Quick start says: its
# prerequisites (Python 3.10 to 3.13 with venv, cmake, a C/C++ compiler), then `make setup`
# (tools/bootstrap.py). The default command is the README's demo, `make demo`.
#
#   docker build -t mecanum_robot .
#   mkdir -p reports && docker run --rm -v "$PWD/reports:/work/reports" mecanum_robot
#   docker run --rm mecanum_robot make test
#
# Python 3.11: it has its lock (requirements/ros-jazzy-pip.py311.lock.txt, which
# requirements.txt includes), and it is the Python the test suite runs on in CI.
# The official image's Python comes with venv and its C headers (Debian's python3 would
# need python3-venv and python3-dev).
FROM python:3.11.13-slim-bookworm

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

# The README's prerequisites: cmake and a C/C++ compiler (build-essential: gcc, g++, make),
# plus tini, so that Ctrl-C and `docker stop` reach the demo's processes.
# hadolint ignore=DL3008
RUN apt-get update \
    && apt-get install -y --no-install-recommends build-essential cmake make tini \
    && rm -rf /var/lib/apt/lists/*

# A user of one's own; build with --build-arg USER_ID="$(id -u)" to own what lands in a
# mounted reports/ folder on the host.
ARG USER_ID=1000
RUN useradd --create-home --non-unique --uid "${USER_ID}" mecanum \
    && mkdir /work \
    && chown mecanum:mecanum /work
USER ${USER_ID}
WORKDIR /work

# Steps 1 and 2 of tools/bootstrap.py alone (.venv and the pinned wheels), from the lock
# files and bootstrap.py only: this slow layer stays cached while the sources change, and
# `make setup` below finds these steps done and skips them.
COPY --chown=mecanum:mecanum requirements/ requirements/
COPY --chown=mecanum:mecanum tools/bootstrap.py tools/
RUN python3 -c "import sys; sys.path.insert(0, 'tools'); import bootstrap; \
bootstrap.check_python(); bootstrap.ensure_venv(); bootstrap.ensure_requirements()"

# The README's setup: the whole of tools/bootstrap.py (overlay and workspace builds).
COPY --chown=mecanum:mecanum . .
RUN make setup

ENTRYPOINT ["/usr/bin/tini", "-g", "--"]
CMD ["make", "demo"]
