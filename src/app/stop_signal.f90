!> A request to stop a load history after its current step: SIGTERM (what
!> a batch system sends at its time limit, and mpirun forwards) or SIGUSR1
!> only sets a flag (C part stop_signal_c.c); the history polls it after
!> each step, agrees on it across ranks, writes its checkpoint and stops.
module stop_signal
  use, intrinsic :: iso_c_binding, only: c_int
  implicit none
  private

  public :: install_stop_signal, stop_requested

  interface
    subroutine fc_stop_signal_install() bind(C, name='fc_stop_signal_install')
    end subroutine fc_stop_signal_install
    integer(c_int) function fc_stop_signal_requested() bind(C, name='fc_stop_signal_requested')
      import :: c_int
    end function fc_stop_signal_requested
  end interface

contains

  !> Catch SIGTERM and SIGUSR1 from now on (this rank).
  subroutine install_stop_signal()
    call fc_stop_signal_install()
  end subroutine install_stop_signal

  !> A stop signal arrived at this rank.
  logical function stop_requested()
    stop_requested = fc_stop_signal_requested() /= 0
  end function stop_requested
end module stop_signal
