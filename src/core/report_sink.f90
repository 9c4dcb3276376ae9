!> Where a component writes its section of the run's report (the PERMON
!> `QPSView` idea): named values, no knowledge of the format. The io layer's
!> json_writer_t is one; a solver of a lower layer writes to this interface.
module report_sink
  use kinds, only: dp, i8
  implicit none
  private

  type, abstract, public :: report_sink_t
  contains
    procedure(put_long_iface), deferred :: put_long
    procedure(put_real_iface), deferred :: put_real
    procedure(put_logical_iface), deferred :: put_logical
    procedure(put_text_iface), deferred :: put_text
    procedure(put_null_iface), deferred :: put_null
    procedure(put_reals_iface), deferred :: put_reals
    procedure(put_longs_iface), deferred :: put_longs
  end type report_sink_t

  abstract interface
    subroutine put_long_iface(self, key, value)
      import :: report_sink_t, i8
      class(report_sink_t), intent(inout) :: self
      character(len=*), intent(in) :: key
      integer(i8), intent(in) :: value
    end subroutine put_long_iface
    subroutine put_real_iface(self, key, value)
      import :: report_sink_t, dp
      class(report_sink_t), intent(inout) :: self
      character(len=*), intent(in) :: key
      real(dp), intent(in) :: value
    end subroutine put_real_iface
    subroutine put_logical_iface(self, key, value)
      import :: report_sink_t
      class(report_sink_t), intent(inout) :: self
      character(len=*), intent(in) :: key
      logical, intent(in) :: value
    end subroutine put_logical_iface
    subroutine put_text_iface(self, key, value)
      import :: report_sink_t
      class(report_sink_t), intent(inout) :: self
      character(len=*), intent(in) :: key, value
    end subroutine put_text_iface
    !> A value that does not exist (JSON null).
    subroutine put_null_iface(self, key)
      import :: report_sink_t
      class(report_sink_t), intent(inout) :: self
      character(len=*), intent(in) :: key
    end subroutine put_null_iface
    subroutine put_reals_iface(self, key, values)
      import :: report_sink_t, dp
      class(report_sink_t), intent(inout) :: self
      character(len=*), intent(in) :: key
      real(dp), intent(in) :: values(:)
    end subroutine put_reals_iface
    subroutine put_longs_iface(self, key, values)
      import :: report_sink_t, i8
      class(report_sink_t), intent(inout) :: self
      character(len=*), intent(in) :: key
      integer(i8), intent(in) :: values(:)
    end subroutine put_longs_iface
  end interface
end module report_sink
