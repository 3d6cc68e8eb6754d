#pragma once
// Mattes mutual information on several work units with a result that does not depend on which
// work unit finishes first. Internal to the rigid registration (included by its .cxx alone: the
// ITK templates stay out of the library's interface).
//
// ITK 5.2's Mattes metric computes each work unit's joint histogram separately and adds them in
// work-unit order, but for a transform with global support (the rigid one) every sample's
// derivative contribution goes into one shared histogram derivative: each work unit buffers a few
// hundred of them and adds them under a lock whenever its buffer fills, and once more as it
// finishes. The order of those additions follows the threads' timing, so the same inputs gave
// transforms up to 3e-4 mm apart; the registration therefore ran on one work unit, one core.
//
// Here each work unit's buffer holds every sample it is given (no addition before the end: the
// buffers are enlarged once the stock threader has sized them), the per-thread finishing step
// adds nothing, and the buffers are added after the threads have joined, work unit 0 first. The
// samples are split into contiguous ranges by the work-unit count alone, which is fixed here
// (WorkUnits, whatever the machine's cores), so the sums, and the transform, are the same to the
// last bit on every run and every machine.
#include <itkMattesMutualInformationImageToImageMetricv4.h>

#include <algorithm>
#include <cstddef>

namespace brainshift {

template <class TImage>
class DeterministicMattesMetric : public itk::MattesMutualInformationImageToImageMetricv4<TImage, TImage>
{
public:
  ITK_DISALLOW_COPY_AND_MOVE(DeterministicMattesMetric);
  using Self = DeterministicMattesMetric;
  using Superclass = itk::MattesMutualInformationImageToImageMetricv4<TImage, TImage>;
  using Pointer = itk::SmartPointer<Self>;
  itkNewMacro(Self);
  itkTypeMacro(DeterministicMattesMetric, MattesMutualInformationImageToImageMetricv4);

  /// The samples' split: four contiguous ranges, on as many threads as ITK's pool has.
  static constexpr itk::ThreadIdType WorkUnits = 4;

  /// Nothing is added here: the buffers wait for addInOrder, after the threads have joined.
  void FinalizeThread(const itk::ThreadIdType) override {}

  /// How many work units the last evaluation's derivative was split over (0 before one).
  std::size_t derivativeWorkUnits() const { return this->m_ThreaderDerivativeManager.size(); }

private:
  /// The stock threader, with the buffers enlarged before the threads run and added in order
  /// after they have joined, before the stock step scales them and makes the derivative.
  template <class TPartitioner>
  class Threader
    : public itk::MattesMutualInformationImageToImageMetricv4GetValueAndDerivativeThreader<TPartitioner, typename Superclass::Superclass,
                                                                                           Superclass>
  {
  public:
    ITK_DISALLOW_COPY_AND_MOVE(Threader);
    using Self = Threader;
    using Pointer = itk::SmartPointer<Self>;
    itkNewMacro(Self);

  protected:
    Threader() = default;
    void BeforeThreadedExecution() override
    {
      this->ThreaderBase::BeforeThreadedExecution();
      metric().holdEveryContribution();
    }
    void AfterThreadedExecution() override
    {
      metric().addInOrder();
      this->ThreaderBase::AfterThreadedExecution();
    }

  private:
    using ThreaderBase =
      itk::MattesMutualInformationImageToImageMetricv4GetValueAndDerivativeThreader<TPartitioner, typename Superclass::Superclass, Superclass>;
    DeterministicMattesMetric& metric() { return *static_cast<DeterministicMattesMetric*>(this->m_Associate); }
  };

protected:
  DeterministicMattesMetric()
  {
    this->m_DenseGetValueAndDerivativeThreader = Threader<itk::ThreadedImageRegionPartitioner<3>>::New();
    this->m_SparseGetValueAndDerivativeThreader = Threader<itk::ThreadedIndexedContainerPartitioner>::New();
    this->m_DenseGetValueAndDerivativeThreader->SetNumberOfWorkUnits(WorkUnits);
    this->m_SparseGetValueAndDerivativeThreader->SetNumberOfWorkUnits(WorkUnits);
  }
  ~DeterministicMattesMetric() override = default;

private:
  bool derivativeBuffered() const { return this->GetComputeDerivative() && !this->HasLocalSupport(); }

  /// Every work unit's buffer longer than its share of the domain: it never fills, so nothing is
  /// added while the threads run. A sample fills one row per moving-image bin of its Parzen window
  /// (the cubic B-spline's four); ITK's partitioners give each of the `used` work units at most
  /// ceil(points / requested) samples, and used <= requested, so ceil(points / used) samples is
  /// a work unit's most.
  void holdEveryContribution()
  {
    if (!derivativeBuffered() || this->m_ThreaderDerivativeManager.empty()) return;
    constexpr std::size_t rowsPerSample = 4;
    const std::size_t points = this->GetUseSampledPointSet() ? std::size_t(this->GetFixedSampledPointSet()->GetNumberOfPoints())
                                                             : std::size_t(this->GetVirtualRegion().GetNumberOfPixels());
    const std::size_t used = this->m_ThreaderDerivativeManager.size(), share = (points + used - 1) / used;
    for (auto& buffer : this->m_ThreaderDerivativeManager) {
      buffer.Initialize(rowsPerSample * share + 1, buffer.GetCachedNumberOfLocalParameters(), &this->m_JointPDFDerivativesLock,
                        this->m_JointPDFDerivatives);
    }
  }

  /// The work units' contributions added to the shared histogram derivative, work unit 0 first.
  /// The sum must still be empty: anything in it was added while the threads ran, in their order.
  void addInOrder()
  {
    if (!derivativeBuffered()) return;
    const auto* sum = this->m_JointPDFDerivatives->GetBufferPointer();
    const std::size_t length = this->m_JointPDFDerivatives->GetBufferedRegion().GetNumberOfPixels();
    if (std::any_of(sum, sum + length, [](auto value) { return value != 0; })) {
      itkExceptionMacro("a work unit's derivative buffer filled before the threads joined: the sum would depend on their timing");
    }
    for (auto& buffer : this->m_ThreaderDerivativeManager) buffer.BlockAndReduce();
  }
};

} // namespace brainshift
