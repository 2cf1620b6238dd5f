// The command-line check the benchmark programs share: --help or -h prints the usage text to
// stdout (exit 0), any other argument count than expected prints it to stderr (exit 2).
#ifndef KDG_PROGRAM_ARGS_HPP
#define KDG_PROGRAM_ARGS_HPP

#include <cstdio>
#include <string>

// -1: the arguments are as expected, go on; otherwise the exit code.
static int check_args(int argc, char ** argv, int expected, const char * usage)
{
  if (argc == 2 && (std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h"))
  {
    std::printf(usage, argv[0]);
    return 0;
  }
  if (argc != expected)
  {
    std::fprintf(stderr, usage, argv[0]);
    return 2;
  }
  return -1;
}

#endif
