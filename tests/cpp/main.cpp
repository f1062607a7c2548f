// doctest entry point for the C++ suite (tests/cpp mirrors core/).
#define DOCTEST_CONFIG_IMPLEMENT_WITH_MAIN
#include <doctest/doctest.h>
