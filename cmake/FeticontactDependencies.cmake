# All dependencies come from Debian 12 packages. A missing one stops the
# configuration with the name of the package to install.

find_package(MPI COMPONENTS Fortran QUIET)
if(NOT MPI_Fortran_FOUND)
  message(FATAL_ERROR "MPI for Fortran not found: apt-get install libopenmpi-dev openmpi-bin")
endif()
if(NOT MPI_Fortran_HAVE_F08_MODULE)
  message(FATAL_ERROR "MPI has no mpi_f08 module: apt-get install libopenmpi-dev (Open MPI >= 4)")
endif()

find_package(LAPACK QUIET)
if(NOT LAPACK_FOUND)
  message(FATAL_ERROR "LAPACK not found: apt-get install liblapack-dev libblas-dev")
endif()

find_package(MUMPS)
if(NOT MUMPS_FOUND)
  message(FATAL_ERROR "MUMPS not found: apt-get install libmumps-dev")
endif()

find_package(METIS)
if(NOT METIS_FOUND)
  message(FATAL_ERROR "METIS not found: apt-get install libmetis-dev")
endif()

set(HDF5_PREFER_PARALLEL TRUE)
find_package(HDF5 COMPONENTS Fortran QUIET)
if(NOT HDF5_FOUND OR NOT HDF5_IS_PARALLEL)
  message(FATAL_ERROR "parallel HDF5 with Fortran not found: apt-get install libhdf5-openmpi-dev")
endif()
if(NOT TARGET feticontact::hdf5)
  add_library(feticontact::hdf5 INTERFACE IMPORTED)
  set_target_properties(feticontact::hdf5 PROPERTIES
    INTERFACE_INCLUDE_DIRECTORIES "${HDF5_Fortran_INCLUDE_DIRS}"
    INTERFACE_LINK_LIBRARIES "${HDF5_Fortran_LIBRARIES}")
endif()

find_program(MPIEXEC_EXECUTABLE NAMES mpiexec mpirun)
message(STATUS "feticontact: MPI ${MPI_Fortran_VERSION}, MUMPS ${MUMPS_INCLUDE_DIR}, "
               "METIS ${METIS_LIBRARY}, HDF5 ${HDF5_VERSION} (parallel)")
