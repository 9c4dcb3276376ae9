# Build types: Release (optimized, the default) and Debug (runtime checks and
# floating point traps; what CI builds the tests with). Unused dummy arguments
# are allowed: the default no-op bindings of abstract types have them.
if(NOT CMAKE_BUILD_TYPE AND NOT CMAKE_CONFIGURATION_TYPES)
  set(CMAKE_BUILD_TYPE Release CACHE STRING "Build type: Release or Debug" FORCE)
endif()

if(NOT CMAKE_Fortran_COMPILER_ID STREQUAL "GNU")
  message(WARNING "feticontact is tested with gfortran only; flags below are gfortran's")
endif()

set(CMAKE_Fortran_FLAGS "${CMAKE_Fortran_FLAGS} -std=f2018 -ffree-line-length-132 -fimplicit-none")
# -march=native unless FETICONTACT_NATIVE=OFF (valgrind cannot run AVX-512 code:
# profile with -DFETICONTACT_NATIVE=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo).
option(FETICONTACT_NATIVE "Optimize for the build machine's CPU (-march=native)" ON)
set(_native "")
if(FETICONTACT_NATIVE)
  set(_native "-march=native")
endif()
set(CMAKE_Fortran_FLAGS_RELEASE "-O3 ${_native} -funroll-loops")
set(CMAKE_Fortran_FLAGS_RELWITHDEBINFO "-O3 -g ${_native} -funroll-loops")
set(CMAKE_Fortran_FLAGS_DEBUG
    "-O0 -g -fcheck=all -ffpe-trap=invalid,zero,overflow -fbacktrace -finit-real=snan -finit-integer=-2147483647 -Wall -Wextra -Wno-compare-reals -Wno-maybe-uninitialized -Wno-unused-dummy-argument")
