#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# The kinematics core is pure math: no file I/O. Fails when a library given here
# references a file-I/O function of the C library, POSIX or iostreams (an undefined
# symbol in `nm` of the archive), naming the object file and the symbol.
# Reading and writing files belongs to kinematics/io (servoarm_kin_io).
#   check_no_file_io.sh <nm> <library.a>...
set -u
nm=$1
shift
# C stdio and POSIX file calls (64-bit variants included), and the C++ file streams.
bad='^(fopen|fopen64|freopen|freopen64|fdopen|fread|fwrite|fclose|fgets|fputs|fprintf|fscanf|fflush|tmpfile|open|open64|openat|openat64|creat|creat64|read|write|pread|pread64|pwrite|pwrite64|close|fstat|fstat64|stat|stat64|lstat|lstat64|__fxstat|__fxstat64|__xstat|__xstat64|fsync|fdatasync|rename|renameat|unlink|unlinkat|mkstemp|mkstemp64|opendir|readdir|readdir64|mmap|mmap64)(@.*)?$|basic_[io]?fstream|basic_filebuf'
status=0
for lib in "$@"; do
  if [ ! -f "$lib" ]; then
    echo "$lib: no such library"
    status=1
    continue
  fi
  # "file.o:" headers, then "U symbol" lines (demangled, so the stream classes read as such)
  out=$("$nm" -C --undefined-only "$lib" 2>&1) || { echo "$lib: $nm failed: $out"; status=1; continue; }
  found=$(printf '%s\n' "$out" | awk -v bad="$bad" '
    /:$/ { obj = $0; sub(/:$/, "", obj); next }
    $1 == "U" { sym = $0; sub(/^[ \t]*U[ \t]+/, "", sym); if (sym ~ bad) printf "%s: %s uses %s\n", lib, obj, sym }' lib="$(basename "$lib")")
  if [ -n "$found" ]; then
    printf '%s\n' "$found"
    status=1
  fi
done
if [ $status -eq 0 ]; then
  echo "no file I/O in: $*"
else
  echo "the kinematics core must not do file I/O: put it in kinematics/io (servoarm_kin_io)"
fi
exit $status
