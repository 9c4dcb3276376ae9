!> Named kinds and the MPI datatypes that match them.
module kinds
  use, intrinsic :: iso_fortran_env, only: real64, int32, int64
  use mpi_f08, only: MPI_Datatype, MPI_DOUBLE_PRECISION, MPI_INTEGER, MPI_INTEGER8
  implicit none
  private

  integer, parameter, public :: dp = real64   !< working precision
  integer, parameter, public :: ip = int32    !< default integer (indices, counts)
  integer, parameter, public :: i8 = int64    !< large counts, byte sizes

  type(MPI_Datatype), parameter, public :: MPI_REAL_DP = MPI_DOUBLE_PRECISION
  type(MPI_Datatype), parameter, public :: MPI_INT_IP = MPI_INTEGER
  type(MPI_Datatype), parameter, public :: MPI_INT_I8 = MPI_INTEGER8

  integer, parameter, public :: path_len = 1024  !< length of file names
  integer, parameter, public :: name_len = 32    !< length of option strings
end module kinds
