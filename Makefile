# Two commands from nothing: `make demo` and `make test` (each creates .venv first).
VENV ?= .venv
PYTHON ?= python3
PY := $(VENV)/bin/python
STAMP := $(VENV)/.monet-installed
# The ROS wheels re-exec Python with their library path; never inherit another venv's state.
unexport _ROS_WHEELS_BOOTSTRAP_COMPLETE

.PHONY: venv tf2_msgs demo test lint docs bench clean browser-deps

venv: $(STAMP)

$(STAMP): requirements.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements.txt
	$(PY) -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation -e .
	$(PY) -c "import rclpy, torch, cv2, numba, mcap, rosbags, h5py, pandas, pynwb, ndx_pose, flask, selenium; print('environment ready: torch', torch.__version__)"
	@if command -v cmake >/dev/null && command -v c++ >/dev/null; then \
	    tools/build_tf2_msgs.sh $(VENV) || echo 'note: tf2_msgs not built: TF is off, its tests skip'; \
	else echo 'note: no cmake / C++ compiler: tf2_msgs not built, TF is off, its tests skip'; fi
	touch $(STAMP)

# tf2_msgs (no pip wheel) built from its message definition with the wheels' rosidl generators.
tf2_msgs: $(STAMP)
	tools/build_tf2_msgs.sh $(VENV)

demo: $(STAMP)
	$(PY) -m monet_ros.cli pipeline

test: $(STAMP) browser-deps
	$(PY) -m pytest

# The browser tests of `monet label` drive Debian's chromium through its chromedriver
# (never a downloaded driver): installed here when missing and apt-get exists (as root, or
# with sudo); without them those tests are skipped.
browser-deps:
	@if [ ! -x /usr/bin/chromedriver ] && command -v apt-get >/dev/null 2>&1; then \
	  SUDO=$$([ "$$(id -u)" = 0 ] || echo sudo); \
	  $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive \
	    $$SUDO apt-get install -y -q chromium chromium-driver || \
	  echo 'chromium + chromium-driver not installed: monet label browser tests will skip'; \
	fi

lint: $(STAMP)
	$(PY) -m ruff check .

# The user guide (docs/, mkdocs.yml) as a static site in site/; a broken link is an error.
docs: $(STAMP)
	$(PY) -m mkdocs build --strict

bench: $(STAMP)
	for script in bench/*.py; do $(PY) $$script || exit 1; done

clean:
	rm -rf $(VENV) build install log site *.egg-info
