!> The settings of the output (`&output`, docs/INPUT.md): where the results
!> go, their name, and what is written. The one home of their defaults,
!> ranges and namelist variables; used by the run and its report.
module output_settings
  use kinds, only: name_len, path_len
  use settings_base, only: settings_t, refuse
  implicit none
  private

  type, extends(settings_t), public :: output_settings_t
    character(len=path_len) :: directory = 'output'  !< where results go
    character(len=name_len) :: run_name = 'cube'  !< run name, file prefix
    logical :: write_hdf5 = .true.  !< HDF5 + XDMF fields
    logical :: write_report = .true.  !< report.json
  contains
    procedure :: check => output_settings_check
    procedure :: group => output_settings_group
    procedure :: variables => output_settings_variables
    procedure :: read_namelist => output_settings_read
    procedure :: write_namelist => output_settings_write
  end type output_settings_t

contains

  !> The first value out of its range: `variable` its name ('' if none),
  !> `rule` the allowed values, `got` the value(s).
  subroutine output_settings_check(self, variable, rule, got)
    class(output_settings_t), intent(in) :: self
    character(len=:), allocatable, intent(out) :: variable, rule, got
    variable = ''
    rule = ''
    got = ''
    if (len_trim(self%directory) == 0) then
      call refuse('directory', 'must not be empty', "''", variable, rule, got)
    else if (len_trim(self%run_name) == 0 .or. verify(trim(self%run_name), &
             'abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.') /= 0) then
      call refuse('run_name', 'must be a non-empty word of letters, digits, _ - .', self%run_name, &
                   variable, rule, got)
    end if
  end subroutine output_settings_check

  !> The namelist group of these variables.
  function output_settings_group(self) result(name)
    class(output_settings_t), intent(in) :: self
    character(len=:), allocatable :: name
    name = 'output'
  end function output_settings_group

  !> The names of the namelist variables (those of read_namelist).
  subroutine output_settings_variables(self, names)
    class(output_settings_t), intent(in) :: self
    character(len=name_len), allocatable, intent(out) :: names(:)
    names = [character(len=name_len) :: 'directory', 'run_name', 'write_hdf5', 'write_report']
  end subroutine output_settings_variables

  !> Read this component's variables from the group text `group`
  !> ('&output ... /').
  subroutine output_settings_read(self, group, status, msg)
    class(output_settings_t), intent(inout) :: self
    character(len=*), intent(in) :: group
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=path_len) :: directory
    character(len=name_len) :: run_name
    logical :: write_hdf5, write_report
    namelist /output/ directory, run_name, write_hdf5, write_report
    directory = self%directory; run_name = self%run_name; write_hdf5 = self%write_hdf5
    write_report = self%write_report
    read (group, nml=output, iostat=status, iomsg=msg)
    if (status /= 0) return
    self%directory = directory; self%run_name = run_name; self%write_hdf5 = write_hdf5
    self%write_report = write_report
  end subroutine output_settings_read

  !> Write this component's variables as the namelist '&output ... /' (strings quoted).
  subroutine output_settings_write(self, lines, status, msg)
    class(output_settings_t), intent(in) :: self
    character(len=*), intent(out) :: lines(:)
    integer, intent(out) :: status
    character(len=*), intent(out) :: msg
    character(len=path_len) :: directory
    character(len=name_len) :: run_name
    logical :: write_hdf5, write_report
    namelist /output/ directory, run_name, write_hdf5, write_report
    directory = self%directory; run_name = self%run_name; write_hdf5 = self%write_hdf5
    write_report = self%write_report
    lines = ''
    write (lines, nml=output, delim='quote', iostat=status, iomsg=msg)
  end subroutine output_settings_write
end module output_settings
