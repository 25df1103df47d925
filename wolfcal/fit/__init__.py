"""wolfcal.fit"""
