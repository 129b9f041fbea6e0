#!/usr/bin/env bash
# Lint (ctest: lint_scratch_names): no test, benchmark or fuzz harness under tests/ writes to a
# fixed or pid-derived scratch name. ctest runs tests in parallel and repeats them
# (--schedule-random --repeat), so two tests writing `TempDir() + "/name"` race, and a pid is not
# unique across repeats. Every scratch path comes from tests/scratch.h (mkdtemp), the one file
# allowed to name the temporary directory or call mkdtemp.
#
#   lint_scratch_names.sh TESTS_DIR   lists each offending line (file:line: reason) and exits 1
#   lint_scratch_names.sh --self-test checks that the lint fails on each pattern it knows
#
# A line that must name one of these for another reason carries `NOLINT(scratch)`.
set -euo pipefail

# reason <TAB> Perl regex, matched against each line with its // comment removed.
RULES=$'gtest TempDir(): names under it are fixed; use tests/scratch.h\t\\bTempDir\\s*\\(\\s*\\)
temp_directory_path: use tests/scratch.h\t\\btemp_directory_path\\b
a scratch name not from tests/scratch.h\t\\b(mkdtemp|mkstemp|mkstemps|tmpnam|tempnam)\\s*\\(
a fixed path in the temporary directory\t"/(tmp|var/tmp|dev/shm)(/|")
a pid-based name (not unique across repeats)\t\\bgetpid\\s*\\(
the temporary directory from the environment\tgetenv\\s*\\(\\s*"(TMPDIR|TEST_TMPDIR)"'

lint() {
  local dir=$1
  RULES="$RULES" find "$dir" -type f \( -name '*.cc' -o -name '*.h' \) ! -path "$dir/scratch.h" \
      -print0 | sort -z | RULES="$RULES" xargs -0 -r perl -ne '
    BEGIN {
      for (split /\n/, $ENV{RULES}) { my ($why, $re) = split /\t/; push @rules, [$why, qr/$re/]; }
    }
    my $line = $_;
    next if $line =~ /NOLINT\(scratch\)/;
    (my $code = $line) =~ s{//.*$}{};
    for my $r (@rules) {
      if ($code =~ $r->[1]) {
        chomp $line; $line =~ s/^\s+//;
        print "$ARGV:$.: $r->[0]: $line\n"; $bad = 1; last;
      }
    }
    close ARGV if eof;  # restart $. for the next file
    END { exit($bad ? 1 : 0) }'
}

self_test() {
  local tmp status=0
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' RETURN
  local -a bad=(
    'const std::string p = ::testing::TempDir() + "/carmba_x.txt";'
    'const auto d = std::filesystem::temp_directory_path() / "carmba_y";'
    'char t[] = "x_XXXXXX"; mkdtemp(t);'
    'std::ofstream("/tmp/carmba_z.csv") << 1;'
    'const std::string d = "carmba_" + std::to_string(::getpid());'
    'const char* t = std::getenv("TMPDIR");'
  )
  for b in "${bad[@]}"; do
    printf '%s\n' "$b" > "$tmp/x_test.cc"
    if lint "$tmp" > /dev/null; then
      echo "self-test: not caught: $b"
      status=1
    fi
  done
  local -a good=(
    'const test::ScratchDir dir("x");  // not ::testing::TempDir() + "/x"'
    'const std::string p = dir.File("out.csv");'
    'EXPECT_FALSE(Load("/nonexistent/scene.yaml").ok());'
    'kill(getpid(), SIGTERM);  // NOLINT(scratch): signals itself'
  )
  for g in "${good[@]}"; do
    printf '%s\n' "$g" > "$tmp/x_test.cc"
    if ! lint "$tmp" > /dev/null; then
      echo "self-test: false alarm: $g"
      status=1
    fi
  done
  [[ $status == 0 ]] && echo "self-test: ${#bad[@]} patterns caught, ${#good[@]} clean lines passed"
  return $status
}

if [[ ${1:-} == --self-test ]]; then
  self_test
elif [[ $# == 1 && -d $1 ]]; then
  if lint "${1%/}"; then
    echo "lint_scratch_names: no fixed scratch name under $1"
  else
    echo "lint_scratch_names: fixed scratch names above; use tests/scratch.h (mkdtemp)" >&2
    exit 1
  fi
else
  echo "usage: $0 TESTS_DIR | --self-test" >&2
  exit 2
fi
