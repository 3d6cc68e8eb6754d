// The kinds of failure the front ends map to exit codes (CONTRACT.md: bad input 2, the method 1; a
// Cancel neither), the cancel flag long operations poll, the warnings they collect, and a
// library's error text made one line.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "FileNames.h"
#include "LibraryMessages.h"

#include <atomic>
#include <string>
#include <type_traits>

int CancelAndWarningsTest(int, char*[])
{
  return brainshift::testing::runTest("CancelAndWarningsTest", [] {
    using namespace brainshift;

    // A Cancel is neither bad input nor a failure of the method; a missing stage is the method's.
    static_assert(!std::is_base_of_v<MethodError, CancelledError> && !std::is_base_of_v<InputError, CancelledError>);
    static_assert(std::is_base_of_v<MethodError, NotAvailableError> && !std::is_base_of_v<InputError, MethodError>);

    throwIfCancelled(nullptr, "rigid registration"); // not cancellable: never throws
    std::atomic<bool> cancel{false};
    throwIfCancelled(&cancel, "rigid registration");
    cancel = true;
    BS_CHECK_THROWS(throwIfCancelled(&cancel, "tissue classification"), CancelledError,
                    "tissue classification cancelled");

    Warnings warnings;
    warn(&warnings, "the scan has 3 NaN voxels; they were set to 0");
    warn(&warnings, "the overlay fmri was resampled");
    BS_CHECK(warnings.size() == 2 && warnings[0] == "the scan has 3 NaN voxels; they were set to 0");
    {
      MutedStderr quiet; // no list: printed (to the muted stderr), not lost and not thrown
      warn(nullptr, "printed, not collected");
    }
    BS_CHECK(warnings.size() == 2);

    BS_CHECK(oneLine("ITK ERROR: NiftiImageIO(0x55d0c0a1b2c0): Could not read header of x.nii:\n  more\n") ==
             "Could not read header of x.nii");
    BS_CHECK(oneLine("\n\n  \nfirst real line  \nsecond") == "first real line");
    BS_CHECK(oneLine("").empty());

    BS_CHECK(hasExtension("/data/Scan.NII.GZ", {".nii", ".nii.gz"}));
    BS_CHECK(!hasExtension("/data/scan.nii.gz.bak", {".nii", ".nii.gz"}));
    BS_CHECK(lowerCaseFileName("/Data/Folder/PreOp.NRRD") == "preop.nrrd");
  });
}
