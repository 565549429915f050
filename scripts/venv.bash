# Sourced by scripts/run and scripts/test: make the project venv once, then leave it alone.
# pip runs only when the venv is new, setup.py changed since the last install, the venv was
# installed from another checkout, or it lacks the extras asked for; a stamp file per extras
# set in the venv holds setup.py's hash and this checkout's path. So after set-up both
# scripts start in well under a second and work with no network.
#   ensure_venv EXTRAS    (EXTRAS: "" for the package alone, "test,bench" for the suite;
#                          the extra `fast`, numba, comes with either where it has a wheel)
# Needs: root (this checkout, absolute) and venv set by the caller. The venv is made with
# $ARM_SIM_PYTHON (default python3); a Python older than setup.py's python_requires is
# refused in one line before pip runs (the pinned numpy and scipy would not install).

setup_stamp() {   # what a stamp must hold for this checkout's setup.py
  local hash
  if command -v sha256sum >/dev/null 2>&1; then
    hash=$(sha256sum "$root/setup.py" | cut -d' ' -f1)
  else
    hash=$(python3 -c 'import hashlib,sys; print(hashlib.sha256(open(sys.argv[1],"rb").read()).hexdigest())' "$root/setup.py")
  fi
  printf '%s %s\n' "$hash" "$root"
}

python_too_old() {   # PYTHON WHAT FIX: true, after one line, when PYTHON is older than setup.py asks
  local python="$1" what="$2" fix="$3" need have
  need=$(sed -n 's/.*python_requires *= *">= *\([0-9][0-9.]*\)".*/\1/p' "$root/setup.py")
  [ -n "$need" ] || return 1
  have=$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null) || {
    echo "scripts: error: $what does not run; arm_sim_ros needs Python $need or newer" >&2
    return 0; }
  if [ "$(printf '%s\n%s\n' "$need" "$have" | sort -V | head -n1)" = "$need" ]; then
    return 1
  fi
  echo "scripts: error: $what is Python $have; arm_sim_ros needs $need or newer (its pinned numpy and scipy do): ${fix//NEED/$need}" >&2
  return 0
}

install_reason() {   # STAMP CREATED: why pip runs now, in words
  local stamp="$1" created="$2" installed_from
  if [ "$created" = 1 ]; then
    echo "the venv is new"
  elif [ ! -f "$stamp" ]; then
    if compgen -G "$venv/.arm_sim_ros-installed*" >/dev/null; then
      echo "the extras ${extras:-of the package alone} are new to this venv"
    else
      echo "nothing of this checkout is installed in it yet"
    fi
  else
    installed_from=$(cut -d' ' -f2- "$stamp")
    if [ "$installed_from" != "$root" ]; then
      echo "it was installed from another checkout, $installed_from"
    else
      echo "setup.py changed since its last install"
    fi
  fi
}

pip_install() {   # ARGS...: pip install, its progress on stderr (a line per package); pip's status
  "$venv/bin/python" -m pip install --disable-pip-version-check --progress-bar off "$@" 2>&1 |
    awk '/^Collecting / { print "scripts: pip: collecting " $2; fflush() }
         /^Installing collected packages:/ { n = split($0, names, ",")
           print "scripts: pip: installing " n " packages (the longest step)"; fflush() }' >&2
  return "${PIPESTATUS[0]}"
}

ensure_venv() {
  local extras="$1" stamp want target created=0 python="${ARM_SIM_PYTHON:-python3}"
  if [ -x "$venv/bin/python" ] && [ ! -f "$venv/.arm_sim_ros-installed${extras:+-$extras}" ] &&
      python_too_old "$venv/bin/python" "the venv $venv" \
        "remove it and run again with ARM_SIM_PYTHON=pythonNEED (or newer)"; then
    exit 1
  fi
  if [ ! -x "$venv/bin/python" ]; then
    python_too_old "$python" "$python" \
      "install Python NEED or newer and run again with ARM_SIM_PYTHON=pythonNEED" && exit 1
    echo "scripts: creating the venv $venv with $python (once)" >&2
    "$python" -m venv "$venv" || {
      echo "scripts: error: could not create a venv at $venv; on Debian/Ubuntu: apt-get install python3-venv" >&2
      exit 1; }
    created=1
  fi
  stamp="$venv/.arm_sim_ros-installed${extras:+-$extras}"
  want=$(setup_stamp)
  if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    return 0
  fi
  target="$root"
  [ -n "$extras" ] && target="$root[$extras]"
  echo "scripts: installing $target into $venv ($(install_reason "$stamp" "$created")); about a minute on first set-up, one line per package" >&2
  # With the extra `fast` (numba: the compiled path) where a wheel exists for this machine;
  # numba is never built from source, and a machine without a wheel runs the pure-Python path.
  pip_install --only-binary numba,llvmlite -e "$root[${extras:+$extras,}fast]" || {
    pip_install -e "$target" || {
      echo "scripts: error: pip could not install the dependencies (no network on first set-up?); run again when online" >&2
      exit 1; }
    echo "scripts: numba (the compiled path) has no wheel for this machine: the simulator runs its pure-Python path (slower, the same numbers)" >&2; }
  printf '%s\n' "$want" > "$stamp"
  # the full install also satisfies the plain one
  [ -n "$extras" ] && printf '%s\n' "$want" > "$venv/.arm_sim_ros-installed"
  echo "scripts: installed; later runs start at once, with no network" >&2
  return 0
}
